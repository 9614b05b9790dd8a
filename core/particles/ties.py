"""Particles tied to objects (a :class:`~.settings.PointConstraint` of kind TIE): a rope's end
tied to a hook, to the world, or to a rigid body — which the rope then swings, and which swings
the rope (two-way coupling).

Binding: a particle of the emitter that is within the constraint's radius of its origin when
first seen (at a sub-step's start) is tied where it is, in the coordinates of the target
object's frame (the world when there is none); it stays tied while it lives.

Kinematic targets (an animated object, the world) hold their particles by pins on the
target's path: rows of Witkin's constraint forces and of the projection, as any point
constraint.

A rigid body simulated in the same world (a leader, stepped first) is moved by its ties: their
rows join the particles' constraint forces and projection together with the body
(:class:`BodyTies`, the ``bodies`` of :class:`~..forces.HardConstraints`: the body's mass and
inertia join the particles' system, and its own step's acceleration the forces' right-hand
side, so a rope holds the body as a pin would). What that gives the body — impulses at the
ties and a velocity change du — moves the anchors for the frame's later sub-steps (the body's
own motion plus h du per sub-step, as a spring mesh's attachment) and goes back to the body
at the frame's end as a :class:`~..world.Reaction` with the move it made meanwhile. The
impulses the body takes are exactly those the particles lose, so the rope and the body
together keep their momentum. The body's own motion within the frame is taken as its step
made it, from its velocity at the start to that at the end at a constant acceleration, in the
particles' sub-steps (:class:`_Body`): where its anchors are and how fast they move agree,
which a light rope needs (a mismatch kicks it). The forces' share of the body is taken once
per step: a tie to a body needs the symplectic Euler integrator.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..forces import Pins
from ..transforms import (
    TransformPath, cross, inverse_affine, matrix_rotation_vector, rotation_vector_matrix,
    transform_points,
)
from ..world import BodyInertia, Reaction, merged

TIE = "TIE"


@dataclass
class _Body:
    """A body the ties pull during one frame interval (``dt`` long): its inertia at the
    frame's end, its path over the frame, the velocity change du (6: linear, angular) its
    ties gave it so far and how far that moved it (its centre's ``shift`` [m] and ``turn``
    (3, 3) about it).

    Its centre moves, before the ties, as its own step took it: from its velocity at the
    start to that at the end at a constant acceleration, in steps of the particles' sub-step
    h (where the path is a straight line), so that the anchors' positions and velocities
    agree and the ties hold it without the jolts a mismatch would give a light rope; it turns
    as its path does."""

    inertia: BodyInertia
    path: TransformPath
    dt: float
    h: float
    du: np.ndarray = field(default_factory=lambda: np.zeros(6))
    shift: np.ndarray = field(default_factory=lambda: np.zeros(3))  # of its centre [m]
    turn: np.ndarray = field(default_factory=lambda: np.eye(3))  # about its centre

    def __post_init__(self):
        self._local = transform_points(inverse_affine(self.path.m1), self.inertia.centre[None])
        self.start = self.path_centre(0.0)
        self.acceleration = (self.inertia.velocity[:3] - self.inertia.velocity0) / self.dt

    def path_centre(self, s: float) -> np.ndarray:
        """Its centre of mass on its path at ``s`` of the frame."""
        return transform_points(self.path.matrices(s), self._local)[0]

    def centre(self, s: float) -> np.ndarray:
        """Its centre of mass at ``s`` (the end of a sub-step of h) before the ties moved it:
        symplectic Euler steps of h at its constant acceleration, as the particles take."""
        tau = s * self.dt
        return self.start + self.inertia.velocity0 * tau + \
            0.5 * self.acceleration * tau * (tau + self.h)

    def velocity(self, s: float) -> np.ndarray:
        """(6,) its velocity at ``s``, the ties' du included."""
        return np.concatenate([self.inertia.velocity0 + self.acceleration * s * self.dt,
                               self.inertia.velocity[3:]]) + self.du

    def point(self, local: np.ndarray, s: float) -> np.ndarray:
        """World positions at ``s`` of points (k, 3) in its path's frame: turned with the
        path, carried with the centre, and moved by the ties."""
        p = transform_points(self.path.matrices(s), local) - self.path_centre(s)
        return self.turned(p + self.centre(s), self.centre(s))

    def local(self, x: np.ndarray, s: float) -> np.ndarray:
        """The inverse of :meth:`point`: where world points (k, 3) at ``s`` are in the path's
        frame."""
        p = self.turned(x, self.centre(s), back=True) - self.centre(s) + self.path_centre(s)
        return transform_points(inverse_affine(self.path.matrices(s)), p)

    def turned(self, p: np.ndarray, centre: np.ndarray, back: bool = False) -> np.ndarray:
        """Points p (k, 3) carried by the ties' move (about ``centre``, the centre before
        it); ``back``: the inverse."""
        if back:
            return centre + (p - centre - self.shift) @ self.turn
        return centre + self.shift + (p - centre) @ self.turn.T

    def moved(self, d: np.ndarray) -> None:
        """The ties moved it by d (6: its centre [m], a rotation vector about it [rad])."""
        self.shift = self.shift + d[:3]
        self.turn = rotation_vector_matrix(d[3:]) @ self.turn

    def reaction_move(self) -> np.ndarray:
        """(6,) where the ties put it against where its own step left it: its centre (the
        shift, and the end of its parabola against its step's end) and a rotation vector."""
        return np.concatenate([self.shift + self.centre(1.0) - self.inertia.centre,
                               matrix_rotation_vector(self.turn)])


class TieFrame:
    """The ties of one frame interval: each TIE constraint's target path (None: the world) and
    the bodies of the world its coupled ties pull.

    Args: inputs: the interval's FrameInputs (emitters, colliders, the leaders' bodies).
    h: the particles' sub-step [s].
    """

    def __init__(self, inputs, h: float):
        colliders = {c.name: c for c in inputs.colliders}
        self.paths: dict[str, TransformPath | None] = {}
        self.coupled: dict[str, str] = {}  # constraint name -> body name
        self.bodies: dict[str, _Body] = {}
        self.reactions: list[Reaction] = []
        for ef in inputs.emitters:
            for c in ef.constraints:
                if c.kind != TIE:
                    continue
                if c.target in inputs.bodies and c.target in colliders:
                    col = colliders[c.target]
                    path = TransformPath(col.matrix0, col.matrix1, col.matrices)
                    self.coupled[c.name] = c.target
                    self.bodies.setdefault(c.target, _Body(inputs.bodies[c.target], path,
                                                           inputs.frame_dt, h))
                else:
                    path = TransformPath(c.target0, c.target1) if c.target else None
                self.paths[c.name] = path

    def substep(self, state, emitters, s0: float, s1: float, t: float, h: float
                ) -> tuple[list, BodyTies | None]:
        """A sub-step's ties (from ``s0`` to ``s1`` of the frame, time ``t``): pins on the
        kinematic targets' paths, and the ties to bodies (None: none), their anchors at the
        sub-step's end. Each body first moves on by h times the velocity its ties gave it;
        particles within a tie's radius not yet tied are tied (``state.ties``: constraint
        name -> (ids, local positions, "body" or "path": which frame they are in))."""
        for body in self.bodies.values():
            body.moved(h * body.du)
        pins, tied = [], []
        for e, ef in enumerate(emitters):
            for c in ef.constraints:
                if c.kind != TIE:
                    continue
                ids, local = self._bind(state, e, c, s0)
                if not len(ids):
                    continue
                i = state.index_of(ids)
                path = self.paths[c.name]
                if c.name not in self.coupled:
                    p0 = local if path is None else transform_points(path.matrices(s0), local)
                    p1 = local if path is None else transform_points(path.matrices(s1), local)
                    pins.append(Pins(i, p0, (p1 - p0) / h, t))
                    continue
                body = self.bodies[self.coupled[c.name]]
                p1 = body.point(local, s1)
                u = body.velocity(s1)
                r = p1 - body.centre(s1) - body.shift
                tied.append((i, p1, u[:3] + cross(u[3:], r), self.coupled[c.name]))
        if not tied:
            return pins, None
        names = list(dict.fromkeys(b for *_, b in tied))
        i, anchor, anchor_v, body = (np.concatenate(a) for a in zip(*(
            (i, p, v, np.full(len(i), names.index(b))) for i, p, v, b in tied)))
        return pins, BodyTies(self, names, s1, i, anchor, anchor_v, body)

    def _bind(self, state, emitter: int, c, s: float) -> tuple[np.ndarray, np.ndarray]:
        """The ids of the particles tie ``c`` holds (its living ones, and those of
        ``emitter`` now within its radius of its origin, tied where they are) and their
        positions in its target's frame. A target that became a body of the world (or
        stopped being one) ties its particles again where they are."""
        mode = "body" if c.name in self.coupled else "path"
        ids, local, was = state.ties.get(c.name, (np.zeros(0, np.int64), np.zeros((0, 3)),
                                                  mode))
        alive = np.isin(ids, state.particle_id)
        ids, local = ids[alive], local[alive]
        if was != mode:
            local = self._local(c, state.particle_x[state.index_of(ids)], s)
        origin = c.matrix0[:3, 3] + s * (c.matrix1[:3, 3] - c.matrix0[:3, 3])
        near = (state.particle_emitter == emitter) & ~np.isin(state.particle_id, ids) & (
            np.linalg.norm(state.particle_x - origin, axis=1) <= c.radius)
        if near.any():
            ids = np.concatenate([ids, state.particle_id[near]])
            local = np.concatenate([local, self._local(c, state.particle_x[near], s)])
            order = np.argsort(ids)
            ids, local = ids[order], local[order]
        state.ties[c.name] = (ids, local, mode)
        return ids, local

    def _local(self, c, x: np.ndarray, s: float) -> np.ndarray:
        """World points x (k, 3) at ``s`` in the frame of tie ``c``'s target."""
        if c.name in self.coupled:
            return self.bodies[self.coupled[c.name]].local(x, s)
        path = self.paths[c.name]
        return x if path is None else transform_points(inverse_affine(path.matrices(s)), x)

    def frame_reactions(self) -> list[Reaction]:
        """What the ties did to the bodies this frame: their impulses, one reaction per body,
        and the move the ties made it."""
        none = np.zeros((0, 3))
        return merged([*self.reactions, *(Reaction(name, none, none, body.reaction_move())
                                          for name, body in self.bodies.items())])


class BodyTies:
    """The ties of one sub-step to bodies, as constraint rows x_i = anchor (three per tie)
    and the bodies' side of them (:class:`~..forces.HardConstraints`): the rows' gradient in
    the bodies' motions, the bodies' masses and the accelerations they have without the ties
    (gravity: their own step has it in their paths). What the constraint forces of the step
    and the projection give them moves the anchors.

    Args: frame: the TieFrame (its bodies take the changes). names: the bodies, in column
    order. s: the sub-step's end (of the frame). i: (k,) tied particles. anchor, anchor_v:
    (k, 3) where they are held at the sub-step's end and how fast that moves. body: (k,)
    each tie's body (in ``names``).
    """

    def __init__(self, frame: TieFrame, names: list[str], s: float, i: np.ndarray,
                 anchor: np.ndarray, anchor_v: np.ndarray, body: np.ndarray):
        self.frame, self.names = frame, names
        self.i, self.anchor, self.anchor_v, self.body = i, anchor, anchor_v, body
        bodies = [frame.bodies[b] for b in names]
        self.centre = np.array([b.centre(s) + b.shift for b in bodies]).reshape(-1, 3)
        self.spin = np.array([b.velocity(s)[3:] for b in bodies]).reshape(-1, 3)
        self.acceleration = np.array([b.acceleration for b in bodies]).reshape(-1, 3)
        self.impulse = np.zeros((len(i), 3))
        self.forced: tuple[np.ndarray, np.ndarray] | None = None
        self.mass = np.zeros((6 * len(names), 6 * len(names)))
        for k, b in enumerate(bodies):
            self.mass[6 * k:6 * k + 3, 6 * k:6 * k + 3] = b.inertia.mass * np.eye(3)
            self.mass[6 * k + 3:6 * k + 6, 6 * k + 3:6 * k + 6] = b.inertia.inertia

    def free_acceleration(self) -> np.ndarray:
        """(6B,) each body's acceleration without its ties (that of its own step), no angular
        part."""
        out = np.zeros((len(self.names), 6))
        out[:, :3] = self.acceleration
        return out.ravel()

    def forces(self, lam: np.ndarray, accel: np.ndarray) -> None:
        """The force pass solved the rows' multipliers ``lam`` (3k,: forces on the particles
        [N]) and the bodies' accelerations from them ``accel`` (6B,)."""
        self.forced = (lam, accel)

    def commit(self, h: float) -> None:
        """A step of h took the force pass's forces (:meth:`forces`): the bodies' velocities
        change by h times their accelerations, their positions by h^2 times them (symplectic
        Euler, as the particles); the particles took h lam, the bodies the opposite."""
        if self.forced is None:
            return
        lam, accel = self.forced
        self.forced = None
        self.move(h * h * accel)
        self.push(h * accel, h * lam)

    @property
    def count(self) -> int:
        """Its rows."""
        return 3 * len(self.i)

    def rows(self, x: np.ndarray, v: np.ndarray, t: float):
        """The rows x_i - anchor = 0 (their C' against the anchor's velocity; J' v: the
        anchor's centripetal acceleration, w x (w x r), taken off)."""
        rows = Pins(self.i, self.anchor, self.anchor_v, t).rows(x, v, t)
        w = self.spin[self.body]
        rows.jdot_v = -cross(w, cross(w, self.anchor - self.centre[self.body])).ravel()
        return rows

    def columns(self) -> np.ndarray:
        """(3k, 6B) the rows' gradient in the bodies' motions (centre, rotation vector): tie p
        of body b, row k (axis e_k) has -e_k and (r x) row k, r the anchor from the centre."""
        k, r = len(self.i), self.anchor - self.centre[self.body]
        u = np.zeros((k, 3, 6 * len(self.names)))
        cols = 6 * self.body[:, None] + np.arange(6)
        block = np.zeros((k, 3, 6))
        block[:, :, :3] = -np.eye(3)
        block[:, 0, 4], block[:, 0, 5] = -r[:, 2], r[:, 1]
        block[:, 1, 3], block[:, 1, 5] = r[:, 2], -r[:, 0]
        block[:, 2, 3], block[:, 2, 4] = -r[:, 1], r[:, 0]
        np.put_along_axis(u, np.broadcast_to(cols[:, None, :], (k, 3, 6)), block, axis=2)
        return u.reshape(3 * k, -1)

    def move(self, dq: np.ndarray) -> None:
        """The bodies moved by dq (6B: centre, rotation vector each): the anchors with them."""
        d = dq.reshape(-1, 6)
        r = self.anchor - self.centre[self.body]
        self.centre = self.centre + d[:, :3]
        for k, (name, step) in enumerate(zip(self.names, d)):
            self.frame.bodies[name].moved(step)
            mine = self.body == k
            self.anchor[mine] = self.centre[k] + r[mine] @ rotation_vector_matrix(step[3:]).T

    def push(self, du: np.ndarray, impulse: np.ndarray) -> None:
        """The bodies' velocities changed by du (6B) by the rows' ``impulse`` (3k,) on the
        particles (the bodies took the opposite)."""
        d = du.reshape(-1, 6)
        r = self.anchor - self.centre[self.body]
        self.anchor_v = self.anchor_v + d[self.body, :3] + cross(d[self.body, 3:], r)
        self.impulse -= impulse.reshape(-1, 3)
        for name, step in zip(self.names, d):
            self.frame.bodies[name].du += step

    def finish(self, x: np.ndarray) -> None:
        """The impulses on the bodies since the last call, at the tied particles ``x``
        (n, 3), to the frame's reactions."""
        for k, name in enumerate(self.names):
            mine = self.body == k
            self.frame.reactions.append(Reaction(name, x[self.i[mine]].copy(),
                                                 self.impulse[mine].copy()))
        self.impulse[:] = 0.0
