"""The rigid-body system: one frame interval in sub-steps, as a world system.

Per frame: pose the bodies that follow paths (kinematic bodies, colliders) -> find contacts
(broad + narrow phase, speculative) -> warm-start them from last frame's impulses -> colour.
Per sub-step: posed bodies to the sub-step's end -> gravity and damping -> warm start -> solve
(soft, with push-out) -> integrate positions (orientation with L held) -> relax -> restitution
(contacts first touched in this sub-step bounce) -> momenta. At the frame's end the impulses are
kept for the next frame.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..bounds import DEFAULT_BOUNDS, StateBounds
from ..contact import ColliderPaths
from ..errors import SimulationError
from ..transforms import TransformPath, cross, take, tangents
from ..world import SolverSystem, World, WorldFrame
from .frame_inputs import RigidFrameInputs, RigidPaths, RigidReport
from . import contact_solver as cs_
from .contact_set import ContactSet
from . import as_colliders, dynamics, joint_step, sleep, warm
from . import reactions as reactions_
from . import joint_solver as js_
from .joints import FRAME
from . import quaternion as quat
from .bodies import Posed, collider_bodies, frame_bodies, mesh_shapes
from .collide import SPECULATIVE, Bodies, Found, find_contacts, kept_pairs
from .hull_shape import HullSet
from .mesh_contacts import MeshCache
from .model import HULL, RigidBodyModel, RigidBodyState

DEFAULT_SUBSTEPS = 8
# sub-steps between contact searches: contacts are found with the normals of their time, so
# bodies that meet at speed need them refreshed within a frame (1/24 s is long)
COLLIDE_EVERY = 2
# ... but only for the bodies that have moved (or are about to move) this fraction of their size
# since their contacts were last searched, at most a quarter of the speculative margin; the
# others keep their contacts, across frames too (a resting pile is searched once)
REFRESH_FRACTION = 0.02


@dataclass
class _FrameStep:
    state: RigidBodyState
    inputs: RigidFrameInputs
    h: float
    g: np.ndarray
    posed: Posed
    posed_rows: np.ndarray  # rows of the posed bodies (kinematic bodies, then colliders)
    bodies: Bodies
    vel: np.ndarray  # (N, 6) every body's [v, w] during the sub-steps ([m/s], [rad/s])
    inv_mass: np.ndarray  # (N,)
    report: RigidReport
    contacts: ContactSet | None = None
    q0: np.ndarray | None = None  # (N, 4) orientations the contacts' anchors are given at
    x_ref: np.ndarray | None = None  # (N, 3), (N, 4): each body's pose when its contacts
    q_ref: np.ndarray | None = None  # were last searched
    rows: cs_.Rows | None = None  # the contacts' rows and separations (M, S) at the poses now
    separation: np.ndarray | None = None
    awake: np.ndarray | None = None  # indices of the dynamic bodies simulated this frame
    driven: np.ndarray | None = None  # indices of the bodies on their paths this frame
    joints: joint_step.JointStep | None = None
    model: RigidBodyModel | None = None  # the frame's: the joints with their keyed values
    held: tuple = ()  # names of the bodies other systems gave impulses over the frame before

    @property
    def v(self) -> np.ndarray:
        """(N, 3) linear velocities of the bodies (a view of ``vel``)."""
        return self.vel[:len(self.bodies), :3]

    @property
    def w(self) -> np.ndarray:
        """(N, 3) angular velocities of the bodies (a view of ``vel``)."""
        return self.vel[:len(self.bodies), 3:]


class RigidBodySolver:
    """Advances a :class:`RigidBodyState` frame by frame.

    Args:
        model: the frozen model. substeps: sub-steps per frame. bounds: a body beyond them is
        an error. colliders: the caller's collider cache (unused by rigid bodies but shared).
    """

    def __init__(self, model: RigidBodyModel, substeps: int = DEFAULT_SUBSTEPS,
                 bounds: StateBounds = DEFAULT_BOUNDS, colliders: ColliderPaths | None = None,
                 collide_every: int = COLLIDE_EVERY):
        if int(substeps) != substeps or substeps < 1:
            raise ValueError(f"substeps must be an integer >= 1 (got {substeps})")
        self.model, self.substeps, self.bounds = model, int(substeps), bounds
        self.collide_every = max(1, int(collide_every))
        self.colliders = ColliderPaths() if colliders is None else colliders
        self.hulls = _hulls(model)
        self._meshes = MeshCache()  # meshes' hierarchies, kept between frames
        self._pairs = kept_pairs()  # candidate pairs, kept between searches

    # -- the frame ------------------------------------------------------------------------------
    def advance(self, state: RigidBodyState, inputs: RigidFrameInputs) -> RigidReport:
        """Advance ``state`` (in place) by one frame interval: a world of this one system."""
        system = RigidBodySystem(self, state)
        world = World([system], self.colliders)
        return world.advance(inputs.world, {system: inputs.paths}).reports[system]

    def absorb(self, state: RigidBodyState, reactions) -> None:
        """Impulses other systems gave the bodies over the frame just ended
        (:func:`.reactions.absorb`)."""
        reactions_.absorb(self.model, state, reactions)
        self._held = tuple(sorted({r.body for r in reactions}))

    def begin_frame(self, state: RigidBodyState, inputs: RigidFrameInputs, paths) -> _FrameStep:
        """Pose, find and prepare the frame's contacts."""
        model = self.model
        n = model.body_count
        kin = np.array(sorted(int(i) for i in inputs.kinematic), np.int64)
        if len(kin) and (kin[0] < 0 or kin[-1] >= n):
            raise ValueError(f"paths given for bodies {kin.tolist()} of {n}")
        d = np.setdiff1d(np.arange(n), kin)
        state.body_asleep[kin] = False
        colliders = collider_bodies(list(inputs.colliders), inputs.frame)
        paths_ = [TransformPath(inputs.kinematic[int(i)][0], inputs.kinematic[int(i)][-1],
                                inputs.kinematic[int(i)]) for i in kin]
        posed = Posed(paths_ + colliders[3], np.concatenate(
            [model.body_com[kin], np.zeros((len(colliders[3]), 3))]))
        v = np.zeros((n, 3))
        w = np.zeros((n, 3))
        v[d] = state.body_P[d] / model.body_mass[d, None]
        w[d] = dynamics.angular_velocity(state.body_q[d], model.body_inv_inertia[d], state.body_L[d])
        pv, pw = posed.velocity(0.0, 1.0, inputs.frame_dt)
        nk = len(kin)
        v[kin], w[kin] = pv[:nk], pw[:nk]
        bodies = frame_bodies(model, state, colliders, posed, kin, (v, w), self.hulls)
        bodies.v[n:], bodies.w[n:] = pv[nk:], pw[nk:]
        bodies.meshes = mesh_shapes(model, list(inputs.colliders), self._meshes)
        for row, mesh in bodies.meshes.items():  # a Mesh collider's size is its mesh's
            bodies.bound[row] = max(bodies.bound[row], mesh.radius)
        g = np.asarray(inputs.gravity, dtype=np.float64)
        rows = np.concatenate([kin, n + np.arange(len(colliders[0]))]).astype(np.int64)
        inv_mass = np.concatenate([model.body_inv_mass, np.zeros(len(colliders[0]))])
        inv_mass[kin] = 0.0
        if state.joints is None:
            state.joints = model.joints.state()
        live = np.nonzero(~state.joints.joint_broken)[0]
        framed = live[model.joints.joint_b[live] == FRAME]
        vel = np.concatenate([bodies.v, bodies.w], axis=1)
        step = _FrameStep(state, inputs, inputs.frame_dt / self.substeps, g, posed, rows, bodies,
                          np.concatenate([vel, np.zeros((len(framed), 6))]), inv_mass,
                          RigidReport(), driven=kin, held=getattr(self, "_held", ()))
        self._held = ()
        bodies.excluded = np.union1d(model.joints.excluded_pairs(len(bodies)),
                                     _own_colliders(model.body_name, colliders[6], len(bodies)))
        fast = np.linalg.norm(bodies.v, axis=1) + np.linalg.norm(bodies.w, axis=1) * \
            bodies.bound > sleep.WAKE_SPEED
        self._wake_state(step, moving=fast)
        self._collide(step, inputs.frame_dt, state.contacts)
        woken = sleep.wakers(state.body_asleep, state.body_island, step.contacts.ab[:, 0],
                             step.contacts.ab[:, 1], (bodies.dynamic & fast) | bodies.moving)
        if woken.any():  # touched: those islands take part in this frame after all
            state.body_asleep[woken] = False
            state.body_slow[woken] = 0
            self._wake_state(step, bodies.moving)
            self._collide(step, inputs.frame_dt, state.contacts,
                          forced=np.concatenate([woken, np.zeros(len(bodies) - n, bool)]))
        step.model = model if inputs.joint_settings is None else replace(
            model, joints=model.joints.with_values(inputs.joint_settings))
        joint_step.begin(step.model, step, live, framed)
        return step

    def _wake_state(self, step: _FrameStep, moving: np.ndarray) -> None:
        """The frame's awake dynamic bodies; sleeping ones weigh on others as if static."""
        b, m, state = step.bodies, self.model, step.state
        n = m.body_count
        asleep = np.concatenate([state.body_asleep, np.zeros(len(b) - n, bool)])
        free = np.ones(len(b), bool)
        free[step.driven] = False
        free[n:] = False
        b.dynamic = free & ~asleep
        b.sleeping, b.moving = asleep, moving & ~b.dynamic
        step.awake = np.nonzero(b.dynamic[:n])[0]
        step.inv_mass = np.where(b.dynamic, np.concatenate(
            [m.body_inv_mass, np.zeros(len(b) - n)]), 0.0)
        step.v[asleep], step.w[asleep] = 0.0, 0.0

    def _collide(self, step: _FrameStep, duration: float, kept: warm.Kept | None = None,
                 forced: np.ndarray | None = None) -> None:
        """Contacts for the next ``duration`` [s] from the bodies' current poses and velocities:
        searched again for the fresh bodies (:meth:`_fresh`, and ``forced`` ones), kept for
        pairs of the others. ``kept``: the contacts carried from the last frame; None within a
        frame (the contacts in use; nothing happens when no body is fresh). New contacts are
        warm-started from the old ones at the same place (:mod:`.warm`)."""
        b = step.bodies
        b.v, b.w = step.v.copy(), step.w.copy()
        if kept is None:
            fresh = self._fresh(step, duration)
            if not fresh.any():
                return
            old = step.contacts.turned(self._turn(step))
        elif kept.contacts is not None and kept.names == b.name:
            step.x_ref, step.q_ref = kept.x.copy(), kept.q.copy()
            fresh, old = self._fresh(step, duration), kept.contacts
        else:  # the first frame, or the colliders changed: everything is searched
            step.x_ref, step.q_ref = b.x.copy(), b.q.copy()
            fresh, old = np.ones(len(b), bool), None
        if forced is not None:
            fresh |= forced
        b.fresh = fresh
        found = find_contacts(b, duration, step.g, self.collide_every * step.h, self._pairs)
        parts = [self._prepare(b, found, self._remembered(old))]
        if old is not None:
            a_, b_ = old.ab[:, 0], old.ab[:, 1]
            keep = ~(fresh[a_] | fresh[b_]) & (b.dynamic[a_] | b.dynamic[b_])
            parts.append(old.take(np.nonzero(keep)[0]))
        step.contacts = ContactSet.join(parts).coloured(b.dynamic)
        step.q0 = b.q.copy()
        step.x_ref[fresh], step.q_ref[fresh] = b.x[fresh], b.q[fresh]
        self._pose_contacts(step)
        step.report.contacts = max(step.report.contacts, int(step.contacts.valid.sum()))

    def _fresh(self, step: _FrameStep, duration: float) -> np.ndarray:
        """(N,) bodies whose contacts must be searched again: those that have moved, or at
        their speed will move within ``duration``, more than REFRESH_FRACTION of their size
        (bound radius; turning counts at the bound) since their contacts were last searched,
        and at most a quarter of the speculative margin (so two bodies that keep their
        contacts cannot close a gap the last search did not see)."""
        b = step.bodies
        turn = quat.multiply(b.q, quat.conjugate(step.q_ref))
        angle = 2.0 * np.arctan2(np.linalg.norm(turn[:, 1:], axis=1), np.abs(turn[:, 0]))
        speed = np.linalg.norm(step.v, axis=1) + np.linalg.norm(step.w, axis=1) * b.bound
        drift = np.linalg.norm(b.x - step.x_ref, axis=1) + angle * b.bound + speed * duration
        return drift > np.minimum(REFRESH_FRACTION * b.bound, 0.25 * SPECULATIVE)

    def _turn(self, step: _FrameStep) -> np.ndarray:
        """(N, 3, 3) each body's rotation since the contacts' reference orientations."""
        return quat.to_matrix(quat.multiply(step.bodies.q, quat.conjugate(step.q0)))

    def _carried(self, step: _FrameStep) -> warm.Kept:
        """The contacts at the frame's end for the next frame: anchors at the poses now,
        nothing touched yet."""
        cs = step.contacts.turned(self._turn(step))
        cs.touched = cs.impulse[..., 0] > 0.0
        cs.relative = np.zeros_like(cs.relative)
        return warm.Kept(cs, step.x_ref, step.q_ref, step.bodies.name)

    @staticmethod
    def _remembered(cs: ContactSet | None) -> warm.Remembered:
        """The impulses of ``cs`` by place, to warm-start contacts found at the same places."""
        if cs is None:
            return warm.Remembered.none()
        pair = np.broadcast_to(cs.pair[:, None], cs.valid.shape)[cs.valid]
        return warm.remember(pair, cs.place[cs.valid], cs.world_impulses()[cs.valid])

    def _prepare(self, bodies: Bodies, found: Found, memory: warm.Remembered) -> ContactSet:
        """Contact constraints from the found points: anchors, combined coefficients, the
        relative normal velocity (for restitution) and the remembered impulses by place
        (:mod:`.warm`)."""
        a, b, n = found.a, found.b, found.normal
        pair, local = warm.places(a, b, found.point, bodies.x, bodies.q, len(bodies))
        ra, rb = found.point - bodies.x[a], found.point - bodies.x[b]
        rel = np.einsum("ki,ki->k", n, (bodies.v[b] + cross(bodies.w[b], rb))
                        - (bodies.v[a] + cross(bodies.w[a], ra)))
        size = np.where(bodies.dynamic, bodies.bound, np.inf)  # a collider's size says nothing
        tolerance = warm.MATCH_FRACTION * np.minimum(size[a], size[b])
        p = warm.recall(memory, pair, local, tolerance)  # world impulse vectors
        t1, t2 = tangents(n) if len(n) else (n, n)
        impulse = np.stack([np.einsum("ki,ki->k", p, d) for d in (n, t1, t2)], 1) \
            if len(a) else np.zeros((0, 3))
        impulse[:, 0] = np.maximum(impulse[:, 0], 0.0)
        return ContactSet.of_points(
            a, b, pair, place=local, normal=n, point=found.point, xa=bodies.x[a],
            xb=bodies.x[b], separation=found.separation,
            friction=np.sqrt(bodies.friction[a] * bodies.friction[b]),
            restitution=bodies.restitution[a] * bodies.restitution[b], relative=rel,
            impulse=impulse)

    def substep(self, step: _FrameStep, k: int) -> None:
        """Sub-step ``k``: the passes of the module docstring."""
        h = step.h
        s0, s1 = k / self.substeps, (k + 1) / self.substeps
        if k and k % self.collide_every == 0:  # contacts again where bodies have moved
            self._collide(step, (1.0 - s0) * step.inputs.frame_dt)
        cs, vel = step.contacts, step.vel
        self._move_posed(step, s0, s1)
        joint_step.pose(step.model, step, self._inverse_inertia)
        self._forces(step)
        soft = cs_.Softness.of(min(cs_.CONTACT_HERTZ, 0.25 / h), cs_.DAMPING_RATIO, h)
        hard = cs_.Softness.of(min(cs_.STATIC_HERTZ, 0.5 / h), cs_.DAMPING_RATIO, h)
        js = step.joints
        cs_.record_approach(vel, cs, step.rows)
        cs_.impacts(vel, cs, step.rows, step.separation, h)
        cs_.warm_start(vel, cs, step.rows)
        if js.solve is not None:
            js_.warm_start(vel, js.solve, js.impulse)
            js_.solve(vel, js.solve, js.impulse, h, use_bias=True)
        cs_.solve(vel, cs, step.rows, cs_.Scales.of(cs, step.separation, h, soft, hard, True))
        self._integrate(step)
        joint_step.project(step.model, step, self._inverse_inertia,
                           last=k == self.substeps - 1)
        self._pose_contacts(step)  # the bodies moved: arms, inertias and gaps at the new poses
        joint_step.pose(step.model, step, self._inverse_inertia)
        if js.solve is not None:
            js_.solve(vel, js.solve, js.impulse, h, use_bias=False)
        cs_.solve(vel, cs, step.rows, cs_.Scales.of(cs, step.separation, h, soft, hard, False))
        cs_.restitution(vel, cs, step.rows)
        joint_step.break_over(step.model, step, self._inverse_inertia)
        self._store(step, last=k == self.substeps - 1)

    # -- passes ---------------------------------------------------------------------------------
    def _move_posed(self, step: _FrameStep, s0: float, s1: float) -> None:
        """Kinematic bodies, colliders and joints' animated frames to the sub-step's end, with
        the velocity that takes them there (what they impart to the bodies they push or hold)."""
        js = step.joints
        if len(js.rows):
            x, q = js.frames.pose(s1)
            js.x, js.rot = x, quat.to_matrix(q)
            step.vel[js.rows] = np.concatenate(js.frames.velocity(s0, s1, step.h), axis=1)
        if not len(step.posed):
            return
        x, q = step.posed.pose(s1)
        v, w = step.posed.velocity(s0, s1, step.h)
        rows = step.posed_rows
        step.bodies.x[rows], step.bodies.q[rows] = x, q
        step.v[rows], step.w[rows] = v, w

    def _forces(self, step: _FrameStep) -> None:
        """Gravity and damping on the dynamic bodies' velocities."""
        d, m, h = step.awake, self.model, step.h
        step.v[d] += h * step.g
        step.v[d] *= (1.0 / (1.0 + h * m.body_linear_damping[d]))[:, None]
        step.w[d] *= (1.0 / (1.0 + h * m.body_angular_damping[d]))[:, None]

    def _inverse_inertia(self, step: _FrameStep, q: np.ndarray) -> np.ndarray:
        """(N, 3, 3) world inverse inertia (0 for bodies impulses do not move)."""
        out = np.zeros((len(step.bodies), 3, 3))
        d = step.awake
        out[d] = dynamics.world_tensor(q[d], self.model.body_inv_inertia[d])
        return out

    def _pose_contacts(self, step: _FrameStep) -> None:
        """The contacts' rows and separations at the bodies' current poses. Each point's
        anchors are carried with their bodies; its separation is the found one plus how far
        they have moved apart along the normal, and both impulses act at their midpoint. The
        manifold blocks are kept from the contact search (they barely change)."""
        cs, b = step.contacts, step.bodies
        turn_t = self._turn(step).transpose(0, 2, 1)  # (gathered contiguous: faster products)
        a, bb = cs.ab[:, 0], cs.ab[:, 1]
        xa, xb = take(b.x, a)[:, None], take(b.x, bb)[:, None]
        pa = xa + np.matmul(cs.ra, take(turn_t, a))
        pb = xb + np.matmul(cs.rb, take(turn_t, bb))
        step.separation = cs.base + np.einsum("msi,msi->ms", cs.normal, pb - pa)
        mid = 0.5 * (pa + pb)
        step.rows = cs_.rows(cs, step.inv_mass, self._inverse_inertia(step, b.q),
                             mid - xa, mid - xb)

    def _integrate(self, step: _FrameStep) -> None:
        """Positions of the dynamic bodies; their orientation turns with L held, and w is
        re-derived at the new orientation (so torque-free motion keeps L exactly)."""
        d, m, h, b = step.awake, self.model, step.h, step.bodies
        b.x[d] += h * step.v[d]
        q0 = b.q[d]
        r0 = quat.to_matrix(q0)
        L = dynamics.angular_momentum(q0, m.body_inertia[d], step.w[d], r0)
        b.q[d] = dynamics.integrate_orientation(q0, m.body_inv_inertia[d], L, h, r0)
        step.w[d] = dynamics.angular_velocity(b.q[d], m.body_inv_inertia[d], L)

    def _store(self, step: _FrameStep, last: bool) -> None:
        """Momenta and poses into the State; at the frame's end, the impulses by place."""
        d, m, b, state = step.awake, self.model, step.bodies, step.state
        n = m.body_count
        state.body_x[:] = b.x[:n]
        state.body_q[:] = b.q[:n]
        d = np.concatenate([d, step.driven])  # on a path: its momenta are the path's (a body
        # let go leaves with them)
        state.body_P[d] = m.body_mass[d, None] * step.v[d]
        state.body_L[d] = dynamics.angular_momentum(b.q[d], m.body_inertia[d], step.w[d])
        state.joints.joint_impulse[step.joints.ids] = step.joints.impulse
        self._check(step)
        if last:
            self._sleep(step)
            sep = step.separation[step.contacts.valid]
            step.report.overlap = float(max(0.0, -sep.min())) if len(sep) else 0.0
            state.contacts = self._carried(step)
            step.report.moving = int(np.count_nonzero(
                np.linalg.norm(step.v[d], axis=1) > 1e-3))

    def _sleep(self, step: _FrameStep) -> None:
        """Islands at rest for long enough fall asleep (their momenta become zero)."""
        m, b, state, cs = self.model, step.bodies, step.state, step.contacts
        n = m.body_count
        speed = np.linalg.norm(step.v[:n], axis=1) + np.linalg.norm(step.w[:n], axis=1) * \
            m.body_bound
        pinned = np.zeros(n, bool)
        js = step.joints
        held = js.ab[:, 1] >= len(b)  # held by a frame: pinned while an animated one moves
        moving = np.array([not p.static for p in js.frames.paths], bool)
        pinned[js.ab[held, 0][moving[js.ab[held, 1] - len(b)]]] = True
        ca = np.concatenate([cs.ab[:, 0], js.ab[~held, 0]])  # joints join islands as contacts
        cb = np.concatenate([cs.ab[:, 1], js.ab[~held, 1]])
        for this, other in ((ca, cb), (cb, ca)):
            touch = (this < n) & b.moving[other]
            pinned[this[touch]] = True
        now = sleep.update(state.body_asleep, state.body_slow, state.body_island, speed, ca, cb,
                           b.dynamic[:n], pinned)
        state.body_P[now] = 0.0
        state.body_L[now] = 0.0
        step.report.sleeping = int(state.body_asleep.sum())

    def _check(self, step: _FrameStep) -> None:
        state = step.state
        bad = self.bounds.violation(state.body_x, step.v[:self.model.body_count])
        if bad is not None:
            raise SimulationError(f"{bad[1]} — check the initial velocities, overlaps at the "
                                  f"start and gravity, or use more substeps{_held_hint(step)}",
                                  obj=self.model.body_name[bad[0]], frame=step.inputs.frame,
                                  kind="rigid body")


def _held_hint(step: _FrameStep) -> str:
    """What to try when bodies other systems hold blow up: those systems meet the bodies once
    per sub-step of their own, after the bodies took their whole frame (a heavy body landing
    on planks a rope holds drives them a frame's fall into the rope before it answers)."""
    if not step.held:
        return ""
    many = len(step.held) > 1
    named = f'"{step.held[0]}"' + (f" and {len(step.held) - 1} more hang" if many else " hangs")
    return (f" — {named} on a spring mesh or particles, which hold {'them' if many else 'it'} "
            "once per sub-step of their own: raise the Spring Mesh Substeps (Scene > PhysAnim, or the mesh's "
            "Substeps) or the particles' Substeps")


def _own_colliders(bodies: tuple, colliders: tuple, count: int) -> np.ndarray:
    """Keys body * count + collider row of each body and the collider of the same name: a
    body's own object tagged as a collider too (a body never collides with itself)."""
    row = {name: i for i, name in enumerate(bodies)}
    return np.array([row[name] * count + len(bodies) + k for k, name in enumerate(colliders)
                     if name in row], np.int64)


def _hulls(model: RigidBodyModel):
    """(HullSet of the HULL bodies or None, (n,) each body's index in it, -1 for others)."""
    rows = np.nonzero(model.body_shape == HULL)[0]
    index = np.full(model.body_count, -1, np.int64)
    if not len(rows):
        return None, index
    index[rows] = np.arange(len(rows))
    return HullSet.from_ranges(model.hull_points, model.body_hull_start[rows],
                               model.body_hull_count[rows],
                               [model.body_name[i] for i in rows]), index


class RigidBodySystem(SolverSystem):
    """The rigid bodies as one system of a :class:`~physanim.core.world.World`; its own
    per-frame input is the kinematic bodies' paths (body index -> matrices). It leads: its
    dynamic bodies are moving colliders for the other systems of the frame."""

    leads = True

    def __init__(self, solver: RigidBodySolver, state: RigidBodyState, name: str = "rigid bodies"):
        super().__init__(solver, state, name)
        self._shapes = as_colliders.shapes(solver.model)
        self._start = None
        self._momentum0 = None  # the bodies' momenta at the frame's start

    def begin_frame(self, frame: WorldFrame, paths, own) -> None:
        self._start = (self.state.body_x.copy(), self.state.body_q.copy())
        self._momentum0 = self.state.body_P.copy()
        super().begin_frame(frame, paths, own)

    def frame_colliders(self) -> list:
        """Each dynamic body as a collider moving from its pose at the frame's start to its
        pose now."""
        return as_colliders.frames(self.solver.model, self._shapes, self._start,
                                   (self.state.body_x, self.state.body_q))

    def frame_bodies(self) -> dict:
        """Each dynamic body's mass, world inertia, centre of mass and velocity now (and its
        velocity at the frame's start)."""
        return reactions_.bodies(self.solver.model, self.state, self._momentum0)

    def inputs(self, frame: WorldFrame, paths: RigidPaths | None) -> RigidFrameInputs:
        return RigidFrameInputs.of(frame, paths)

    def report(self, step: _FrameStep) -> RigidReport:
        return step.report
