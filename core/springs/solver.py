"""Spring-mesh solver: advances a :class:`SpringMeshState` one frame interval in sub-steps.

Per sub-step: collide (resting contacts: vertices on colliders, and the vertices of faces
resting on a collider's corner, crease or sphere) -> forces (gravity, springs, bending,
virtual springs, drag, wind on faces, contact) -> integrate (any scene integrator; IMPLICIT is
Baraff-Witkin) -> pins (exactly on their animated targets) -> limit strain (optional, Provot)
-> respond (continuous collisions, as particles) -> with IMPLICIT, when vertices hit a
collider or faces must be lifted off its features, the sub-step again with them as landing
constraints (up to LANDING_ROUNDS times; not for hits that only touch a flat one: under
LAND_LIFT, slower than the rest speed, :func:`.landing.touches`) -> keep the colliders'
features off the faces and edges (:mod:`..contact.features`) -> keep the mesh off itself
(optional, :mod:`.self_collision`) -> check (finite, not torn apart).
"""
from __future__ import annotations

import numpy as np

from ..bounds import DEFAULT_BOUNDS, StateBounds
from ..contact import ColliderPaths, ContactForce, Contacts, respond, resting_contacts
from ..contact.features import FaceSet, NearPairs, keep_off_features, resting_on_features
from ..errors import PhysanimError, SimulationError
from ..forces import AnchorSprings, DampedSprings, Gravity
from ..integrators import make_integrator
from ..transforms import TransformPath, inverse_affine, transform_points
from ..world import SolverSettings, World, merged
from .forces import AngularSprings, ConstantForces, LinearDrag, MassShared, hinge_normals
from .bdf2 import BDF2
from .implicit import BaraffWitkin
from .inputs import SpringFrameInputs
from . import attach
from . import landing as landing_
from . import sleep as sleep_
from .model import SpringMeshModel, SpringMeshState
from .self_collision import SelfCollision
from .ode import MeshOde, SubstepForces
from .strain import limit_strain
from .wind import FaceWind
from .frame_step import FrameStep, SpringMeshSystem

TEAR_FACTOR = 50.0  # a spring stretched past this many rest lengths means the solve blew up
LANDING_ROUNDS = 3  # re-solves of a sub-step whose vertices hit colliders (implicit only)
GROUND_ROUNDS = 3  # self-collision passes alternating with the colliders' in a sub-step
LIFT_SHARE = 0.25  # of the self-collision distance: a collider's lift that needs another pass
# sub-steps per frame at least, in frames where attachments hold the mesh on rigid bodies it
# moves (two-way coupling): at one, the exchange of impulses with bodies stepped a frame ahead
# grows without bound (a rope bridge's planks reached 650 km/s by frame 6; stable at two)
COUPLED_SUBSTEPS = 2


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
        self.settings = SolverSettings(integrator, substeps, tolerance, bounds)
        self.model = model
        self.bounds = bounds
        self.colliders = ColliderPaths() if colliders is None else colliders
        self.substeps = self.settings.substeps
        self.integrator_name = integrator
        self.integrator = (BaraffWitkin() if integrator == "IMPLICIT" else BDF2()
                           if integrator == "BDF2" else make_integrator(integrator, tolerance))
        s = model.settings
        self.springs = DampedSprings(model.spring_i, model.spring_j, model.spring_rest,
                                     model.spring_stiffness, model.spring_damping, keep=True)
        self.bending = AngularSprings(model.hinge, model.hinge_rest, s.bend_stiffness,
                                      s.bend_damping, hinge_normals(model.rest_x, model.hinge))
        self.free = ~model.held
        self._inv_mass = np.where(self.free, 1.0 / model.vertex_mass, 0.0)
        self._mass_share = model.vertex_mass / model.vertex_mass.sum()
        # what a spring's length is measured against for tearing: its rest length, and
        # zero-length springs (duplicate vertices) the mesh's scale
        rest = model.spring_rest
        scale = float(np.median(rest[rest > 0])) if np.any(rest > 0) else 1.0
        self._tear_length = np.maximum(rest, scale)
        self.drag = LinearDrag(model.settings.drag)
        edges = model.spring_family == 0
        self.faces = FaceSet.of(model.triangles, np.stack([model.spring_i[edges],
                                                           model.spring_j[edges]], axis=1))
        self._near = NearPairs()  # the colliders' features' candidate pairs, kept between detections
        self.itself = SelfCollision(self.faces, model.vertex_mass, self._inv_mass,
                                    s.self_distance, s.self_friction) \
            if s.self_collision else None
        self._sleep = sleep_.Sleep.for_mesh(model.rest_x) if s.sleep else None
        # the vertices the animated rest shape moves: hard pins and soft (PIN) springs' anchors
        self._anchored = ~self.free
        for vs in model.virtual:
            if vs.mode == "PIN":
                self._anchored[vs.index] = True
        self._check_stability(frame_dt / self.substeps, frame)

    def __setstate__(self, saved: dict) -> None:
        """A solver saved before spring meshes slept resumes awake, never sleeping."""
        self.__dict__.update({"_sleep": None, "_anchored": None, **saved})

    def close(self) -> None:
        """End what the solver runs beside the bake (self-collision's helper process); a later
        step runs without it."""
        if getattr(self, "itself", None) is not None:
            self.itself.close()

    @property
    def asleep(self) -> bool:
        """Whether the mesh sleeps (:mod:`.sleep`): its next frame is skipped if nothing
        around it changes."""
        return self._sleep is not None and self._sleep.asleep

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

    # -- the frame ------------------------------------------------------------------------------
    def advance(self, state: SpringMeshState, inputs: SpringFrameInputs) -> int:
        """Advance ``state`` (in place) by one frame interval: a world of this one system.
        Returns collisions handled."""
        system = SpringMeshSystem(self, state)
        world = World([system], self.colliders)
        return world.advance(inputs.world, {system: inputs.drive}).reports[system]

    def begin_frame(self, state: SpringMeshState, inputs: SpringFrameInputs,
                    paths: list) -> FrameStep:
        # attached to them, not colliding with them; nor with its own object as a collider
        # (that is its undeformed shape, which the mesh starts on)
        apart = {a.target for a in self.model.attachments if not a.collide}
        apart.add(self.model.settings.name)
        every, paths = paths, [p for p in paths if p.frame.name not in apart]
        g = np.asarray(inputs.gravity, dtype=np.float64)
        rest0 = inputs.rest0 if inputs.rest0 is not None else self.model.rest_x
        rest1 = inputs.rest1 if inputs.rest1 is not None else rest0
        held = attach.frame_paths(self.model, state, inputs.colliders, inputs.targets,
                                  inputs.bodies, inputs.frame) \
            if self.model.attachments or inputs.bodies else None
        body = next((b for b in held.coupled if b), None) if held is not None else None
        if body is not None and not isinstance(self.integrator, BaraffWitkin):
            raise self._fail(f'an attachment to the rigid body "{body}" moves it with the '
                             f"mesh, which needs the IMPLICIT integrator (this mesh uses "
                             f"{self.integrator_name})", inputs.frame)
        substeps = self.substeps if body is None else max(self.substeps, COUPLED_SUBSTEPS)
        h = inputs.frame_dt / substeps
        step = FrameStep(state, inputs, paths, h, g, rest0, rest1,
                          2.0 * float(np.linalg.norm(g)) * h + 1e-4, held=held,
                          substeps=substeps)
        if self._sleep is not None:
            coupled = held is not None and any(b is not None for b in held.coupled)
            step.conditions = sleep_.conditions(self.integrator_name, h, inputs, every,
                                                self._anchored, rest0, rest1, coupled)
            step.asleep = self._sleep.sleeps(step.conditions)
            step.start = None if step.asleep else state.x.copy()
        return step

    def substep(self, step: FrameStep, k: int) -> None:
        """Sub-step ``k``: the passes of the module docstring (none while the mesh sleeps)."""
        if step.asleep:
            return
        state, inputs, h = step.state, step.inputs, step.h
        s0, s1 = k / step.substeps, (k + 1) / step.substeps
        t = inputs.t0 + k * h
        pin_x1 = step.rest0 + s1 * (step.rest1 - step.rest0)
        pin_v = (step.rest1 - step.rest0) / inputs.frame_dt
        if step.held is not None:
            attach.hold(self.model, state, step.held, s0, s1, h, pin_x1, pin_v)
        start = state.x.copy() if (step.paths and self.faces) or self.itself else None
        contact = resting_contacts(step.paths, state.x, state.v, s0, step.rest_speed)
        if step.paths and self.faces:  # faces resting on features: their points rest too (on a body
            # stepped first, the coupling takes them as pressed on it: not through a feature)
            contact = resting_on_features(step.paths, self.faces, state.x, state.v,
                                          self._inv_mass, s0, step.rest_speed,
                                          frozenset(inputs.bodies), self._near).merged(contact)
        forces = self._forces(step, t, s0, s1)
        solved = self._solve(step, forces, contact, t, s0, s1, pin_x1, pin_v)
        touched = [contact]
        outside = self._outside(state.v, state.v)
        if solved is not None:
            x, v, collided, touched, outside = solved
            x[~self.free], v[~self.free] = pin_x1[~self.free], pin_v[~self.free]
            if self.faces:
                touched = [*touched, self._keep_off(step, start, x, v, s0, s1, outside)]
            state.x, state.v, step.hits = x, v, step.hits + collided
        if self.itself is not None:  # its own impulses: equal and opposite, none from outside
            try:
                self._keep_apart(step, start, touched, s1)
            except SimulationError as exc:  # (self-collision's own: it knows no name or frame)
                if exc.obj is not None:
                    raise
                raise self._fail(exc.detail, inputs.frame, SimulationError) from exc
        if outside is not None:
            self._react(step, touched, outside, s1)
        self._check(state, inputs.frame)
        if step.start is not None and k == step.substeps - 1 and self._sleep.settle(
                step.conditions, self.free, step.start, state.x, state.v, inputs.frame_dt):
            state.v = np.zeros_like(state.v)

    def _keep_off(self, step: FrameStep, x0: np.ndarray, x: np.ndarray, v: np.ndarray,
                  s0: float, s1: float, outside: np.ndarray | None) -> Contacts:
        """The colliders' corners, creases and spheres kept off the mesh's faces and edges
        (:mod:`..contact.features`): x and v in place; their impulses join ``outside``."""
        before = v.copy() if outside is not None else None
        kept = keep_off_features(step.paths, self.faces, x0, x, v, self._inv_mass, s0, s1,
                                 step.rest_speed, near=self._near)
        if outside is not None and len(kept):
            outside += self.model.vertex_mass[:, None] * (v - before)
        return kept

    def _keep_apart(self, step: FrameStep, start: np.ndarray, touched: list, s1: float) -> None:
        """The mesh kept off itself (:mod:`.self_collision`); the colliders then stop whatever
        its pushes drove at them (a layer on a two-sided plane pushed through it would stay
        beneath). A layer pushed down onto the ground under another one, and lifted back
        by it, could come up through the other: when a collider moved points by a quarter of
        the distance or more, the points it moved count as on it (they hardly move in the
        mesh's own pushes; those already on it move a hundredth as far again in the
        separating passes) and the mesh is kept off itself again, up to GROUND_ROUNDS
        times. If the colliders' last lift was still that large, the mesh is kept off itself
        once more (the lifted points hardly moving: they press the colliders by a hundredth of
        a push at most), and the points of any pair still crossed go back to where they started
        the sub-step (the self-collision fail safe): a crossing left at a sub-step's end would
        never be undone, as the next one's tests only see pairs cross during it."""
        state = step.state
        grounded = np.unique(np.concatenate([c.index for c in touched]))
        before = state.x.copy()
        self.itself.begin_substep()
        # one round more than GROUND_ROUNDS: the last lift may have brought a layer near the
        # one above, so they are parted once more, the lifted points hardly moving (a vertex
        # was left at 40 % of the distance), and the colliders stop what that drove at them
        # (a layer was left 2 cm under the ground)
        lifted = np.zeros(0, np.int64)
        for round_ in range(GROUND_ROUNDS + 1):
            step.hits += self.itself.keep_apart(start, state.x, state.v, step.rest_speed,
                                                grounded, step.h, lifted)
            if not step.paths:
                return
            pushed = state.x
            x, v, count, _ = respond(step.paths, before, pushed, state.v, state.v, s1, s1,
                                     step.h, step.rest_speed)
            state.x, state.v, step.hits = x, v, step.hits + count
            if round_ == GROUND_ROUNDS:
                break
            lift = np.linalg.norm(x - pushed, axis=1)
            if lift.max(initial=0.0) < LIFT_SHARE * self.itself.distance:
                return  # too little to carry a layer through another kept a distance off
            lifted = np.union1d(lifted, np.flatnonzero(lift > 0.0))
            grounded = np.union1d(grounded, lifted)
        self.itself.fail_safe(start, state.x, state.v)

    def _react(self, step: FrameStep, touched: list, outside: np.ndarray, s1: float) -> None:
        """Two-way coupling with the bodies stepped first this frame: the attached ones move
        with the mesh (solved implicitly), and every body takes back the impulses that held
        the mesh's vertices on it or pushed them off it (:mod:`.attach`)."""
        state, held, bodies = step.state, step.held, step.inputs.bodies
        if not bodies:
            return
        pushed = np.zeros(self.model.vertex_count, bool)
        hits: dict[str, list] = {}
        for c in touched:
            pushed[c.index] = True
            for ci in np.unique(c.collider[c.collider >= 0]):
                name = step.paths[ci].frame.name
                if name in bodies:
                    hits.setdefault(name, []).append(c.index[c.collider == ci])
        hits = {b: np.unique(np.concatenate(i)) for b, i in hits.items()}
        hits = {b: i[self.free[i]] for b, i in hits.items()}
        pressed = self._pressed_on(step) if held is not None else {}
        if held is not None and (any(b is not None for b in held.coupled) or pressed):
            attach.couple(self.model, held, self.integrator, pressed, outside, state.x,
                          state.v, step.h, s1)
        elif not any(len(i) for i in hits.values()):
            return
        step.reactions = merged([*step.reactions, *attach.react(
            self.model, held, self.model.vertex_mass, self.free, pushed, hits, outside,
            state.x, state.v, step.h, s1)])

    def _pressed_on(self, step: FrameStep) -> dict:
        """The vertices the last implicit step held on the surfaces of bodies stepped first:
        body -> (vertices, normals)."""
        if not isinstance(self.integrator, BaraffWitkin) or self.integrator.last_solve is None:
            return {}
        f = self.integrator.last_solve[1]
        if not len(f.pressed):
            return {}
        rows = np.searchsorted(f.contact.index, f.pressed)
        which = f.contact.collider[rows]
        out = {}
        for ci in np.unique(which[which >= 0]):
            name = step.paths[ci].frame.name
            if name in step.held.bodies:
                sel = which == ci
                out[name] = (f.pressed[sel], f.normal[sel])
        return out

    # -- passes ---------------------------------------------------------------------------------
    def _forces(self, step: FrameStep, t: float, s0: float, s1: float) -> SubstepForces:
        """Gravity, springs, bending, drag, virtual springs, wind on faces, force objects."""
        model, inputs = self.model, step.inputs
        virtual = self._virtual(step.state, inputs, t, step.h, s0, s1)
        carried = self.itself.forces(model.vertex_count) if self.itself is not None else None
        carried = [ConstantForces(carried)] if carried is not None else []
        winds = [FaceWind(model.triangles, w) for w in inputs.winds if len(model.triangles)]
        return SubstepForces(
            all=[Gravity(tuple(step.g)), self.springs, self.bending, self.drag, *virtual, *winds,
                 *(MassShared(f, self._mass_share) for f in inputs.fields), *carried],
            stiff=[self.springs, self.bending, self.drag, *virtual, *winds],
            potentials=[self.springs, self.bending, *carried], gravity=step.g)

    def _virtual(self, state: SpringMeshState, inputs: SpringFrameInputs, t0: float, h: float,
                 s0: float, s1: float) -> list:
        forces = []
        for g, vs in enumerate(self.model.virtual):
            a0, a1 = self._anchors(state, inputs, g, vs, s0, s1)
            forces.append(AnchorSprings(vs.index, a0, a1, t0, h,
                                        np.full(len(vs.index), vs.rest_length),
                                        vs.stiffness * vs.weight, vs.damping * vs.weight))
        return forces

    def _anchors(self, state, inputs: SpringFrameInputs, g: int, vs, s0: float, s1: float):
        """Where virtual-spring group ``g``'s vertices are pulled at s0 and s1: the animated
        rest shape (PIN), points fixed in the target (ATTACH, bound on the first frame) or the
        target's origin (DISTANCE)."""
        if vs.mode == "PIN":
            rest0 = inputs.rest0 if inputs.rest0 is not None else self.model.rest_x
            rest1 = inputs.rest1 if inputs.rest1 is not None else rest0
            return (rest0[vs.index] + s0 * (rest1[vs.index] - rest0[vs.index]),
                    rest0[vs.index] + s1 * (rest1[vs.index] - rest0[vs.index]))
        if vs.target not in inputs.targets:
            raise self._fail(f"virtual spring target \"{vs.target}\" has no transform",
                             inputs.frame)
        path = TransformPath(*inputs.targets[vs.target])
        m0, m1 = path.matrices(s0), path.matrices(s1)
        if vs.mode == "ATTACH":
            if state.attached[g] is None:
                state.attached[g] = transform_points(inverse_affine(path.m0),
                                                     self.model.rest_x[vs.index])
            return transform_points(m0, state.attached[g]), transform_points(m1, state.attached[g])
        return (np.broadcast_to(m0[:3, 3], (len(vs.index), 3)),
                np.broadcast_to(m1[:3, 3], (len(vs.index), 3)))

    def _solve(self, step: FrameStep, forces: SubstepForces, contact: Contacts, t: float,
               s0: float, s1: float, pin_x1, pin_v):
        """Integrate, then respond to collisions on the vertices' paths; with IMPLICIT, a step
        whose vertices hit a collider is solved again with them landing on it (up to
        LANDING_ROUNDS times). Returns (x, v, collisions, the contacts of the step and of each
        round's hits, the impulses from outside the mesh's forces (implicit only, else None:
        :meth:`_outside`)) after response, or None when there are no colliders (the state
        holds the integrated step)."""
        state, h, paths = step.state, step.h, step.paths
        implicit = isinstance(self.integrator, BaraffWitkin)

        bodies = np.array([k for k, path in enumerate(paths)
                           if path.frame.name in step.inputs.bodies], np.int64)
        flat = landing_.flat(paths, step.inputs.bodies)

        def ode_with(constraints: Contacts) -> MeshOde:
            return MeshOde(state, self.model.vertex_mass, self.free, forces, pin_v, constraints,
                           None if implicit else ContactForce(constraints, h), bodies,
                           step.held is not None and any(b is not None for b in step.held.coupled))

        ode = ode_with(contact)
        x0, v0 = state.x.copy(), state.v.copy()
        landing, collided, first, hits = None, 0, None, [contact]
        for round_ in range(LANDING_ROUNDS + 1):
            if round_:
                # vertices hit a surface during the step: solve the step again with them as
                # constraints landing on it, so their neighbours feel the stop through the
                # springs instead of a projection after the fact (which stretches stiff
                # springs: energy from nowhere)
                state.x, state.v = x0.copy(), v0.copy()
                ode = ode_with(landing)
            self._step(ode, t, h, pin_x1, pin_v, step.inputs.frame)
            solved = state.v.copy()
            if landing is not None:
                landing_.bounce(state.v, landing, step.rest_speed)
            if not paths:
                return None
            x, v, count, hit = respond(paths, x0, state.x, v0, state.v, s0, s1, h,
                                       step.rest_speed)
            collided = max(collided, count)  # the first round finds the step's collisions
            hits.append(hit)
            outside = self._outside(v, solved)
            again = implicit and round_ < LANDING_ROUNDS
            base = landing if landing is not None else contact
            more = landing_.contacts(base, hit, x0, h, self.free, touch=landing_.touches(
                hit, state.x, x, step.rest_speed, flat)) if again else None
            # once no vertex lands anew, the faces the colliders' features reach: the first
            # round's projection of them is the safeguard's fallback
            placed, faced = (x, v), None
            if implicit and self.faces and (first is None or (again and more is None)):
                faced, *placed = landing_.off_features(step.paths, self.faces, x0, x, v,
                                                       self._inv_mass, s0, s1, step.rest_speed,
                                                       self._near, frozenset(step.inputs.bodies))
            if first is None:
                first = (*placed, self._outside(placed[1], solved))
            if again and more is None:
                more = landing_.contacts(base, Contacts.none(), x0, h, self.free, faced)
            if more is None:
                break
            landing = more
        if landing is not None and ode.energy(*first[:2]) < ode.energy(x, v):
            # a safeguard: landing constraints must not end with more energy than projecting
            # the hits (and the faces off the features) after the first solve (a stiff mesh
            # whose landing vertices are forced apart can store more spring energy than that)
            x, v, outside = first
        return x, v, collided, hits, outside

    def _outside(self, v: np.ndarray, solved: np.ndarray) -> np.ndarray | None:
        """(n, 3) [N s] the impulses the sub-step's vertices took from outside the mesh's own
        forces: the implicit solve's (pins, attachments, contacts: its residual) plus what the
        bounces and collisions after it changed (``solved``: velocities the solve left; pinned
        rows keep only the solve's). None for explicit integrators."""
        if not isinstance(self.integrator, BaraffWitkin):
            return None
        bump = self.model.vertex_mass[:, None] * (v - solved)
        bump[~self.free] = 0.0
        return self.integrator.residual() + bump

    def _step(self, system, t: float, h: float, pin_x1, pin_v, frame) -> None:
        """One integrator step, then pins exactly on their targets and the strain limit."""
        state = system.state
        try:
            self.integrator.step(system, t, h)
        except SimulationError as exc:
            raise self._fail(f"the simulation blew up ({exc}) — {self._advice()}", frame,
                             SimulationError) from exc
        state.x[~self.free] = pin_x1[~self.free]
        state.v[~self.free] = pin_v[~self.free]
        model = self.model
        if model.settings.max_stretch > 0.0:
            limited = model.spring_family < 2  # edge and shear springs, not bending ones
            limit_strain(state.x, state.v, model.spring_i[limited], model.spring_j[limited],
                         model.spring_rest[limited], self._inv_mass, model.settings.max_stretch, h)

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
            length = self.springs.geometry(state.x)[1]  # (the next step's forces start there)
            ratio = length / self._tear_length
            worst = int(np.argmax(ratio))
            if ratio[worst] > TEAR_FACTOR and length[worst] > 1e-6:
                raise self._fail(
                    f"spring {int(m.spring_i[worst])}-{int(m.spring_j[worst])} stretched to "
                    f"{ratio[worst]:.0f}x its rest length — the simulation is unstable: "
                    f"{self._advice()}", frame, SimulationError)

    def _advice(self) -> str:
        if self.integrator_name in ("IMPLICIT", "BDF2"):
            return "use more substeps or lower stiffness"
        return "use the IMPLICIT integrator, more substeps or lower stiffness"
