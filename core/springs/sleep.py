"""A spring mesh at rest sleeps: its sub-steps are skipped while nothing around it changes.

A cloth that has settled on a collider or hangs still from its pins is, step after step, a
solve of forces that cancel: every step costs its full passes (contacts, features, the
implicit solve) to move the vertices by micrometres. When, for SLEEP_TIME seconds of frames in
a row under the same conditions, no free vertex has strayed further from where it was at their
start than a creep at the sleep speed would take it in that time (the sleep speed —
SLEEP_SHARE of the mesh's size per second, at most SLEEP_SPEED — times SLEEP_TIME: 1 mm for a
cloth of 2 m or more), and none has moved faster than SWAY times the sleep speed, the mesh
falls asleep: its velocities become zero and its vertices stay where they are, and each
sub-step returns at once. A slow creep sleeps as it did when every frame had to be slower
than the sleep speed; a sway that dies out about where the mesh lies (a corner of a drape
swinging back and forth by a few tenths of a millimetre, its speed rising above the sleep
speed at each pass) no longer keeps the mesh awake until its peaks fall below it; a buzz
faster than SWAY times the sleep speed at the frames' ends, however small, still does.

The conditions are what a sub-step is a function of, apart from the mesh's own state
(:func:`conditions`): the integrator and the sub-step length, gravity, the colliders (each still
over the interval: not moving, not deforming, and the same as when the mesh fell asleep), the
pins' targets — the animated rest shape under hard and soft pins — and the attachments' and
virtual springs' targets (still, and where they were), the force objects (the same, each
steady: drag, attractors, vortices and winds without gusts push a still mesh the same way at
any time), and no attachment to a rigid body (which the mesh's sub-steps move). A rigid body
the mesh lies on is a collider: it must be still too (a sleeping body is), so a mesh asleep
on it hands it no weight while nothing moves, and wakes with the body. Anything else — a
collider keyed to move, a body landing on the mesh (it moves as a collider), gravity keyed, a
force keyed or gusting, pins or targets moving — wakes the mesh for that frame; it sleeps
again only after SLEEP_TIME more of slow frames. As Bullet's sleeping bodies, a mesh creeping slower
than the sleep speed for that long stops: the drape of the cloth benchmark over Suzanne,
asleep from frame 93, ends 0.09 mm from where it lies when baked on without sleeping (0.02 mm
from frame 117 under the earlier rule, every frame slower than the sleep speed, which its
hanging corner's dying sway kept awake 24 frames longer).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..contact import same_frames
from ..forces import Attractor, Drag, Vortex, Wind

SLEEP_SPEED = 2e-3  # [m/s] the largest sleep speed (a cloth of 2 m or more)
SLEEP_SHARE = 1e-3  # [1/s] the sleep speed as a share of the mesh's size (its rest box's diagonal)
SLEEP_TIME = 0.5  # [s] of consecutive slow frames before the mesh sleeps
SWAY = 4.0  # x the sleep speed: the fastest a vertex of a mesh about to sleep may move
# force objects whose push is a function of the mesh's positions and velocities alone (a wind
# only without gusts, which change with time)
STEADY = (Attractor, Drag, Vortex, Wind)


@dataclass(frozen=True)
class Conditions:
    """What a spring mesh's sub-steps are a function of, besides its own state: the
    integrator, the sub-step h [s], gravity, the colliders' frames (each still), the pins'
    and targets' places: ``pins`` (k, 3) the pinned vertices' targets, ``targets`` the
    attachments' and virtual springs' target matrices by name; and the force objects (each
    steady)."""

    integrator: str
    h: float
    gravity: tuple
    colliders: tuple
    pins: np.ndarray
    targets: tuple
    forces: tuple = ()

    def same_as(self, other: Conditions | None) -> bool:
        return (other is not None and (self.integrator, self.h, self.gravity) ==
                (other.integrator, other.h, other.gravity) and
                len(self.forces) == len(other.forces) and
                all(_same_force(a, b) for a, b in zip(self.forces, other.forces)) and
                same_frames(self.colliders, other.colliders) and
                np.array_equal(self.pins, other.pins) and len(self.targets) == len(other.targets)
                and all(na == nb and np.array_equal(a, b)
                        for (na, a), (nb, b) in zip(self.targets, other.targets)))


def conditions(integrator: str, h: float, inputs, paths: list, anchored: np.ndarray,
               rest0: np.ndarray, rest1: np.ndarray, coupled: bool) -> Conditions | None:
    """The conditions of a frame interval's sub-steps, or None when they change within it or
    the mesh must not sleep under them: a collider moving or deforming (``paths``: every
    collider's, those the mesh is attached to without colliding too), a force object that is
    not steady (:data:`STEADY`), pins or targets moving, an attachment to a rigid body
    (``coupled``). ``anchored``: (n,) bool, the vertices held on the animated rest shape
    ``rest0`` -> ``rest1`` (hard pins, soft pins' springs)."""
    forces = (*inputs.winds, *inputs.fields)
    if coupled or not all(_steady(f) for f in forces) or not all(p.still for p in paths):
        return None
    if not np.array_equal(rest0[anchored], rest1[anchored]):
        return None
    targets = []
    for name in sorted(inputs.targets):
        m0, m1 = inputs.targets[name]
        if not np.array_equal(m0, m1):
            return None
        targets.append((name, np.asarray(m0)))
    return Conditions(integrator, float(h), tuple(float(g) for g in inputs.gravity),
                      tuple(p.frame for p in paths), rest1[anchored], tuple(targets), forces)


class Sleep:
    """Whether a spring mesh sleeps, and how long it has been slow (see the module
    docstring). ``speed``: its sleep speed [m/s]."""

    anchor: np.ndarray | None = None  # (a sleep saved before anchors: none yet)

    def __init__(self, speed: float):
        self.speed = float(speed)
        self.asleep = False
        self.slow = 0.0  # [s] of consecutive slow frames under self.conditions
        self.conditions: Conditions | None = None
        self.anchor = None  # (n, 3) where the vertices were when those slow frames began

    @classmethod
    def for_mesh(cls, rest_x: np.ndarray) -> Sleep:
        """The sleep of a mesh with rest positions ``rest_x`` (n, 3)."""
        size = float(np.linalg.norm(np.ptp(rest_x, axis=0))) if len(rest_x) else 0.0
        return cls(min(SLEEP_SPEED, SLEEP_SHARE * size))

    def sleeps(self, now: Conditions | None) -> bool:
        """Whether the frame interval under ``now`` is skipped; a sleeper under other
        conditions wakes."""
        if self.asleep and now is not None and now.same_as(self.conditions):
            return True
        if self.asleep:
            self.asleep, self.slow, self.anchor = False, 0.0, None
        return False

    def settle(self, now: Conditions | None, free: np.ndarray, x0: np.ndarray, x1: np.ndarray,
               v1: np.ndarray, frame_dt: float) -> bool:
        """After a frame interval under ``now`` that took the free vertices from ``x0`` to
        ``x1`` with velocities ``v1`` at its end: whether the mesh falls asleep now (the
        caller then zeroes its velocities). The frame is slow when no free vertex is further
        from where it was when the slow frames began (``x0`` of the first) than the sleep
        speed times the time they take, SLEEP_TIME or, at a frame rate that does not divide
        it, the whole frames that reach it (13 of 1/25 s: a creep just slower than the sleep
        speed sleeps at any frame rate), and none moved faster than SWAY times the sleep speed
        over the frame or at its end."""
        same = now is not None and now.same_as(self.conditions)
        if not same or self.anchor is None or self.anchor.shape != x0.shape:
            self.slow, self.anchor = 0.0, x0.copy()
        fast = now is None or self.speed <= 0.0 or _faster(free, x0, x1, v1, frame_dt,
                                                           SWAY * self.speed) or \
            _strayed(free, self.anchor, x1, self.speed * max(SLEEP_TIME, self.slow + frame_dt))
        if fast:  # the slow frames, if any, begin at this frame's end
            self.slow, self.anchor = 0.0, x1.copy()
        else:
            self.slow += frame_dt
        self.conditions = now
        # (a share of a frame short counts: 12 frames of 1/24 s sum to a hair under 0.5 s)
        self.asleep = not fast and self.slow >= SLEEP_TIME - 1e-9
        return self.asleep


def _steady(force) -> bool:
    """Whether a force object pushes a still mesh the same way at every time."""
    return type(force) in STEADY and not (isinstance(force, Wind) and force.noise > 0.0)


def _same_force(a, b) -> bool:
    """Whether two force objects' frames are the same force (the same kind and values)."""
    try:
        return type(a) is type(b) and bool(a == b)
    except ValueError:  # values that compare element-wise: taken as changed
        return False


def _faster(free: np.ndarray, x0: np.ndarray, x1: np.ndarray, v1: np.ndarray,
            frame_dt: float, speed: float) -> bool:
    """Whether any free vertex moved faster than ``speed`` over the interval (on average) or
    is faster at its end."""
    return _longer(v1[free], speed) or _strayed(free, x0, x1, speed * frame_dt)


def _strayed(free: np.ndarray, anchor: np.ndarray, x1: np.ndarray, distance: float) -> bool:
    """Whether any free vertex is further than ``distance`` from its ``anchor``."""
    return _longer((x1 - anchor)[free], distance)


def _longer(rows: np.ndarray, length: float) -> bool:
    """Whether any of the vectors ``rows`` (k, 3) is longer than ``length``."""
    return bool(np.einsum("ij,ij->i", rows, rows).max(initial=0.0) > length * length)
