"""Spring-mesh solver: advances a :class:`SpringMeshState` one frame interval in sub-steps.

Per sub-step: collide (resting contacts) -> forces (gravity, springs, bending, virtual springs,
drag, wind on faces, contact) -> integrate (any scene integrator; IMPLICIT is Baraff-Witkin)
-> pins (exactly on their animated targets) -> limit strain (optional, Provot) -> respond
(continuous collisions, as particles) -> with IMPLICIT, when vertices hit a collider, the
sub-step again with them as landing constraints (up to LANDING_ROUNDS times) -> check (finite,
not torn apart).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..bounds import DEFAULT_BOUNDS, StateBounds
from ..errors import PhysanimError, SimulationError
from ..contact import ColliderFrame, ColliderPaths, ContactForce, Contacts, respond, resting_contacts
from ..forces import AnchorSprings, DampedSprings, Gravity, ParticleView, Wind
from ..forces.springs import scatter_add
from ..integrators import make_integrator
from ..transforms import TransformPath, inverse_affine, transform_points
from .forces import AngularSprings, LinearDrag, MassShared
from .implicit import BaraffWitkin
from .model import SpringMeshModel, SpringMeshState
from .strain import limit_strain

TEAR_FACTOR = 50.0  # a spring stretched past this many rest lengths means the solve blew up
LANDING_ROUNDS = 3  # re-solves of a sub-step whose vertices hit colliders (implicit only)


@dataclass
class SpringFrameInputs:
    """One frame interval [t0, t0 + frame_dt] of a spring mesh's world.

    Args:
        frame: scene frame at the start (messages). t0 [s], frame_dt [s]. gravity (3,).
        rest0, rest1: (n, 3) animated rest positions (world) at start/end — pin targets.
        targets: object name -> (m0, m1) world matrices of virtual-spring targets.
        colliders: analytic or mesh colliders. winds: wind force objects (pressure on faces).
        fields: other force objects (drag, attractor, vortex, ...): they act on the whole mesh
            as on one particle, shared by the vertices in proportion to their mass.
    """

    frame: int
    t0: float
    frame_dt: float
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    rest0: np.ndarray | None = None
    rest1: np.ndarray | None = None
    targets: dict = field(default_factory=dict)
    colliders: Sequence[ColliderFrame] = ()
    winds: Sequence[Wind] = ()
    fields: Sequence = ()


def _bounce(v: np.ndarray, landing: Contacts, rest_speed: float) -> None:
    """After a re-solved step the landing vertices are on the surface, still approaching it at
    their landing speed: they leave it at restitution times that speed (relative to the
    surface; a bounce slower than ``rest_speed`` ends in contact), as the collision pass would
    have made them."""
    sel = landing.held
    idx, n = landing.index[sel], landing.normal[sel]
    surface_vn = np.einsum("ij,ij->i", landing.surface_velocity[sel], n)
    approach = landing.normal_speed[sel] - surface_vn
    out = -landing.restitution[sel] * np.minimum(approach, 0.0)
    out = np.where(out < rest_speed, 0.0, out)
    vn = np.einsum("ij,ij->i", v[idx], n)
    v[idx] += (surface_vn + out - vn)[:, None] * n


@dataclass(frozen=True)
class FaceWind:
    """Wind on faces: with p = strength (d + gusts) [N/m^2] the pressure vector, a triangle of
    area A and unit normal n gets f = A [(p . n) n + c_t (p - (p . n) n)]: the pressure on the
    side facing the wind plus skin friction along it (c_t = SKIN_FRICTION; it is what streams a
    flag out). A third goes to each corner."""

    SKIN_FRICTION = 0.25

    triangles: np.ndarray
    wind: Wind

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        tri = self.triangles
        a, b, c = p.x[tri[:, 0]], p.x[tri[:, 1]], p.x[tri[:, 2]]
        cross = np.cross(b - a, c - a)  # |cross| = 2 A, direction = normal
        w = self.wind
        pressure = np.broadcast_to(np.asarray(w.direction) * w.strength, cross.shape)
        if w.noise:
            pressure = pressure + (w.strength * w.noise) * w.field((a + b + c) / 3.0, p.t)
        norm = np.sqrt(np.einsum("ij,ij->i", cross, cross))
        area = 0.5 * norm
        n = cross / np.where(norm > 0, norm, 1.0)[:, None]
        normal = np.einsum("ij,ij->i", pressure, n)[:, None] * n
        f = (area / 3.0)[:, None] * (normal + self.SKIN_FRICTION * (pressure - normal))
        for k in range(3):
            scatter_add(f_out, tri[:, k], f)


class _MeshSystem:
    """The spring mesh as integrators see it: flat y = [x, v] with derivative [v, f/m], plus
    the richer interface of the Baraff-Witkin stepper. Pinned vertices move with their targets.

    ``contact``: the vertices touching colliders. Explicit integrators see them as a constraint
    on the accumulated forces (``constraint``, a :class:`ContactForce`); the implicit stepper
    enforces ``contact`` as velocity constraints instead (``constraint`` None)."""

    def __init__(self, state: SpringMeshState, mass: np.ndarray, free: np.ndarray, forces: list,
                 pin_x0: np.ndarray, pin_v: np.ndarray, t0: float, contact: Contacts,
                 constraint: ContactForce | None):
        self.state = state
        self.mass = mass
        self.free = free
        self.forces = forces
        self.contact = contact
        self.constraint = constraint
        self._pin_x0, self._pin_v, self._t0 = pin_x0, pin_v, t0
        self.n = len(mass)
        self.dim = 6 * self.n

    # --- the Witkin & Baraff interface ---------------------------------------------------------
    def get_state(self) -> np.ndarray:
        return np.concatenate([self.state.x.ravel(), self.state.v.ravel()])

    def set_state(self, y: np.ndarray) -> None:
        n = self.n
        self.state.x = y[:3 * n].reshape(n, 3).copy()
        self.state.v = y[3 * n:].reshape(n, 3).copy()

    def forces_at(self, t: float, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        f = np.zeros_like(x)
        view = ParticleView(x, v, self.mass, t)
        for force in self.forces:
            force.apply(view, f)
        if self.constraint is not None:
            self.constraint.constrain(view, f)  # last: it cancels what presses into surfaces
        return f

    def derivative(self, t: float, y: np.ndarray) -> np.ndarray:
        n = self.n
        x, v = y[:3 * n].reshape(n, 3), y[3 * n:].reshape(n, 3)
        a = self.forces_at(t, x, v) / self.mass[:, None]
        a[~self.free] = 0.0
        v = np.where(self.free[:, None], v, self._pin_v)
        return np.concatenate([v.ravel(), a.ravel()])

    # --- Baraff-Witkin extras ------------------------------------------------------------------
    @property
    def x(self):
        return self.state.x

    @x.setter
    def x(self, value):
        self.state.x = value

    @property
    def v(self):
        return self.state.v

    @v.setter
    def v(self, value):
        self.state.v = value

    def energy(self, x: np.ndarray, v: np.ndarray) -> float:
        """Kinetic + gravitational + spring + bending energy [J] of the free vertices' motion
        (what an implicit step must not increase when nothing drives the mesh)."""
        m = self.mass
        e = 0.5 * float(np.sum(m[:, None] * v * v))
        for force in self.forces:
            if isinstance(force, Gravity):
                e -= float(np.sum(m * (x @ np.asarray(force.g))))
            elif isinstance(force, DampedSprings):
                e += force.energy(x)
            elif isinstance(force, AngularSprings) and len(force.hinge):
                e += force.energy(x)
        return e

    def weight_norm(self) -> float:
        g = next((f.g for f in self.forces if isinstance(f, Gravity)), (0.0, 0.0, 0.0))
        return float(np.linalg.norm(g) * np.linalg.norm(self.mass[self.free])) or \
            float(np.linalg.norm(self.mass))

    def pinned_velocity(self, t: float) -> np.ndarray:
        return self._pin_v

    def linearize(self, t, x, v) -> list:
        """Jacobian blocks of every force at (x, v) that has them, built once per implicit step."""
        view = ParticleView(x, v, self.mass, t)
        return [force.linearize(view) for force in self.forces if hasattr(force, "linearize")]


class SpringMeshSolver:
    """Advances one spring mesh frame by frame.

    Args:
        model: the frozen model. integrator: name from the scene menu. substeps: per frame.
        tolerance: RK45 tolerance (the implicit solve has its own, BaraffWitkin.TOLERANCE).
        frame_dt: frame length [s] (used to check explicit stability up front). frame: start
        frame (messages). bounds: a vertex beyond them (position or speed) is an error.
        colliders: makes each frame's collider paths and keeps what lasts between frames
            (shared with the other systems of a bake; default: a new one).
    """

    def __init__(self, model: SpringMeshModel, integrator: str = "IMPLICIT", substeps: int = 1,
                 tolerance: float = 1e-4, frame_dt: float = 1 / 24, frame: int | None = None,
                 bounds: StateBounds = DEFAULT_BOUNDS, colliders: ColliderPaths | None = None):
        if int(substeps) != substeps or substeps < 1:
            raise ValueError(f"substeps must be an integer >= 1 (got {substeps})")
        self.model = model
        self.bounds = bounds
        self.colliders = ColliderPaths() if colliders is None else colliders
        self.substeps = int(substeps)
        self.integrator_name = integrator
        self.integrator = (BaraffWitkin() if integrator == "IMPLICIT"
                           else make_integrator(integrator, tolerance))
        s = model.settings
        self.springs = DampedSprings(model.spring_i, model.spring_j, model.spring_rest,
                                 model.spring_stiffness, model.spring_damping)
        self.bending = AngularSprings(model.hinge, model.hinge_rest, s.bend_stiffness,
                                      s.bend_damping)
        self.free = ~model.pinned
        self._inv_mass = np.where(self.free, 1.0 / model.vertex_mass, 0.0)
        self._mass_share = model.vertex_mass / model.vertex_mass.sum()
        self._check_stability(frame_dt / self.substeps, frame)
        self._attach_local = self._attachments()

    def _fail(self, message: str, frame, cls=PhysanimError):
        return cls(message, obj=self.model.settings.name, frame=frame, kind="spring mesh")

    def _check_stability(self, h: float, frame) -> None:
        limit = self.integrator.stable_h_omega
        omega = self.springs.max_rate(self.model.vertex_mass)
        if limit is None or omega * h <= limit:
            return
        need = int(np.ceil(omega * h * self.substeps / limit))
        k = float(self.model.spring_stiffness.max())
        raise self._fail(
            f"stiffness {k:g} N/m on vertices of {self.model.vertex_mass.min():.3g} kg oscillates "
            f"at {omega:.3g} rad/s: {self.integrator_name} with {self.substeps} substep(s) "
            f"(h = {h:.3g} s) would explode (it needs h < {limit / omega:.3g} s, about {need:,} "
            "substeps per frame) — use the IMPLICIT integrator, more substeps or a lower stiffness",
            frame)

    def _attachments(self) -> list:
        """Per ATTACH group: its vertices' rest positions in the target's local space; filled on
        the first frame from the target's matrix then."""
        return [None] * len(self.model.virtual)

    def _virtual(self, inputs: SpringFrameInputs, t0: float, h: float, s0: float, s1: float):
        forces = []
        for g, vs in enumerate(self.model.virtual):
            if vs.mode == "PIN":
                rest0 = inputs.rest0 if inputs.rest0 is not None else self.model.rest_x
                rest1 = inputs.rest1 if inputs.rest1 is not None else rest0
                a0 = rest0[vs.index] + s0 * (rest1[vs.index] - rest0[vs.index])
                a1 = rest0[vs.index] + s1 * (rest1[vs.index] - rest0[vs.index])
            else:
                if vs.target not in inputs.targets:
                    raise self._fail(f"virtual spring target \"{vs.target}\" has no transform",
                                     inputs.frame)
                path = TransformPath(*inputs.targets[vs.target])
                m0, m1 = path.matrices(s0), path.matrices(s1)
                if vs.mode == "ATTACH":
                    if self._attach_local[g] is None:
                        self._attach_local[g] = transform_points(
                            inverse_affine(path.m0), self.model.rest_x[vs.index])
                    a0 = transform_points(m0, self._attach_local[g])
                    a1 = transform_points(m1, self._attach_local[g])
                else:
                    a0 = np.broadcast_to(m0[:3, 3], (len(vs.index), 3))
                    a1 = np.broadcast_to(m1[:3, 3], (len(vs.index), 3))
            forces.append(AnchorSprings(vs.index, a0, a1, t0, h,
                                        np.full(len(vs.index), vs.rest_length),
                                        vs.stiffness * vs.weight, vs.damping * vs.weight))
        return forces

    def advance(self, state: SpringMeshState, inputs: SpringFrameInputs) -> int:
        """Advance ``state`` (in place) by one frame interval. Returns collisions handled."""
        model = self.model
        h = inputs.frame_dt / self.substeps
        g = np.asarray(inputs.gravity, dtype=np.float64)
        rest0 = inputs.rest0 if inputs.rest0 is not None else model.rest_x
        rest1 = inputs.rest1 if inputs.rest1 is not None else rest0
        paths = self.colliders.of(inputs.colliders, inputs.frame_dt)
        rest_speed = 2.0 * float(np.linalg.norm(g)) * h + 1e-4
        hits = 0
        for k in range(self.substeps):
            s0, s1 = k / self.substeps, (k + 1) / self.substeps
            t = inputs.t0 + k * h
            pin_x1 = rest0 + s1 * (rest1 - rest0)
            pin_v = (rest1 - rest0) / inputs.frame_dt
            contact = resting_contacts(paths, state.x, state.v, s0, rest_speed)
            forces = [Gravity(tuple(g)), self.springs, self.bending,
                      LinearDrag(model.settings.drag)]
            forces += self._virtual(inputs, t, h, s0, s1)
            forces += [FaceWind(model.triangles, w) for w in inputs.winds if len(model.triangles)]
            forces += [MassShared(f, self._mass_share) for f in inputs.fields]
            implicit = isinstance(self.integrator, BaraffWitkin)

            def system_with(constraints: Contacts, forces=forces, t=t, s0=s0, pin_v=pin_v,
                            implicit=implicit):
                return _MeshSystem(state, model.vertex_mass, self.free, forces,
                                   rest0 + s0 * (rest1 - rest0), pin_v, t, constraints,
                                   None if implicit else ContactForce(constraints, h))

            system = system_with(contact)
            x0, v0 = state.x.copy(), state.v.copy()
            landing, collided, first = None, 0, None
            for round_ in range(LANDING_ROUNDS + 1):
                if round_:
                    # vertices hit a surface during the step: solve the step again with them
                    # as constraints landing on it, so their neighbours feel the stop through
                    # the springs instead of a projection after the fact (which stretches stiff
                    # springs: energy from nowhere)
                    state.x, state.v = x0.copy(), v0.copy()
                    system = system_with(landing)
                self._step(system, t, h, pin_x1, pin_v, inputs.frame)
                if landing is not None:
                    _bounce(state.v, landing, rest_speed)
                if not paths:
                    break
                x, v, count, hit = respond(paths, x0, state.x, v0, state.v, s0, s1, h,
                                           rest_speed)
                collided = max(collided, count)  # the first round finds the step's collisions
                first = (x, v) if first is None else first
                more = None if not (implicit and round_ < LANDING_ROUNDS) else \
                    self._landing(landing if landing is not None else contact, hit, x0, h)
                if more is None:
                    break
                landing = more
            if landing is not None and system.energy(*first) < system.energy(x, v):
                # a safeguard: landing constraints must not end with more energy than
                # projecting the hits after the first solve (a stiff mesh whose landing
                # vertices are forced apart can store more spring energy than that)
                x, v = first
            if paths:
                x[~self.free], v[~self.free] = pin_x1[~self.free], pin_v[~self.free]
                state.x, state.v, hits = x, v, hits + collided
            self._check(state, inputs.frame)
        return hits

    def _step(self, system, t: float, h: float, pin_x1, pin_v, frame) -> None:
        """One integrator step, then pins exactly on their targets and the strain limit."""
        state = system.state
        try:
            self.integrator.step(system, t, h)
        except SimulationError as exc:
            raise self._fail(f"the simulation blew up ({exc}) — use the IMPLICIT integrator, "
                             "more substeps or lower stiffness", frame, SimulationError) from exc
        state.x[~self.free] = pin_x1[~self.free]
        state.v[~self.free] = pin_v[~self.free]
        model = self.model
        if model.settings.max_stretch > 0.0:
            limited = model.spring_family < 2  # edge and shear springs, not bending ones
            limit_strain(state.x, state.v, model.spring_i[limited], model.spring_j[limited],
                         model.spring_rest[limited], self._inv_mass, model.settings.max_stretch, h)

    def _landing(self, base: Contacts, hit: Contacts, x0, h: float) -> Contacts | None:
        """Contacts for re-solving a step in which free vertices hit a collider (``hit``: their
        first collisions, from :func:`~..contact.respond`): each becomes a held constraint
        whose normal velocity is the one that takes it from its start to where the collision
        put it — merged with ``base`` (the step's resting contacts, or the last round's set;
        a resting vertex that was hit lands instead). None when no vertex that is not held
        already was hit."""
        keep = self.free[hit.index] & ~np.isin(hit.index, base.index[base.held])
        if not keep.any():
            return None
        hit = hit.take(keep)
        land_vn = np.einsum("ij,ij->i", hit.point - x0[hit.index], hit.normal) / h
        return base.merged(replace(hit, normal_speed=land_vn, held=np.ones(len(hit), bool)))

    def _check(self, state: SpringMeshState, frame) -> None:
        if not (np.all(np.isfinite(state.x)) and np.all(np.isfinite(state.v))):
            bad = int(np.argwhere(~np.isfinite(state.x).all(1) | ~np.isfinite(state.v).all(1))[0][0])
            raise self._fail(f"vertex {bad} became non-finite (x = {state.x[bad].tolist()}) — "
                             f"{self._advice()}", frame, SimulationError)
        bad = self.bounds.violation(state.x, state.v)
        if bad is not None:
            raise self._fail(f"vertex {bad[0]} {bad[1]} — check gravity, forces and pins, or "
                             "raise the limits in Scene > PhysAnim > Limits", frame,
                             SimulationError)
        m = self.model
        if len(m.spring_i):
            length = np.linalg.norm(state.x[m.spring_i] - state.x[m.spring_j], axis=1)
            # zero-length springs (duplicate vertices) are measured against the mesh's scale
            scale = float(np.median(m.spring_rest[m.spring_rest > 0])) if np.any(
                m.spring_rest > 0) else 1.0
            ratio = length / np.maximum(m.spring_rest, scale)
            worst = int(np.argmax(ratio))
            if ratio[worst] > TEAR_FACTOR and length[worst] > 1e-6:
                raise self._fail(
                    f"spring {int(m.spring_i[worst])}-{int(m.spring_j[worst])} stretched to "
                    f"{ratio[worst]:.0f}x its rest length — the simulation is unstable: "
                    f"{self._advice()}", frame, SimulationError)

    def _advice(self) -> str:
        if self.integrator_name == "IMPLICIT":
            return "use more substeps or lower stiffness"
        return "use the IMPLICIT integrator, more substeps or lower stiffness"
