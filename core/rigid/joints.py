"""Rigid-body joints: settings -> frozen model (structure of arrays) -> state.

A joint joins body A to body B, or to a frame: the world, or an animated object whose motion
the caller gives frame by frame. It is placed by a world frame at the start — a pivot (its
origin) and axes (its rotation's columns x, y, z) — that it holds fixed in each side's body:

    FIXED       the pivot and the axes: the two move as one.
    BALL        the pivot only: B turns freely about it.
    HINGE       the pivot and the z axis: B turns about z only (the angle: B's x axis from
                A's about z). Limits on the angle [rad], a motor, a spring towards angle 0.
    SLIDER      the axes, and the pivot on the z axis: B slides along z only (the distance:
                along z from A's pivot to B's). Limits [m], a motor, a spring towards 0.
    CONE_TWIST  the pivot; B's z axis within ``cone`` [rad] of A's, its twist about it within
                [lower, upper] [rad] when limited (a shoulder, a rag doll's neck).
    SPRING      the pivot softly: a damped spring of zero rest length between the joint's point
                on each side (``stiffness`` [N/m], ``damping`` [N s/m]) — Witkin's soft
                "attach" constraint, solved implicitly (Catto's soft rows); B turns freely.

A joint breaks when the force it carries (the impulse of its pivot over a sub-step / the
sub-step) exceeds ``break_force`` [N]; it then holds nothing and the frame is recorded.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import PhysanimError
from ..validate import frozen

JOINT_KINDS = ("FIXED", "BALL", "HINGE", "SLIDER", "CONE_TWIST", "SPRING")
FIXED, BALL, HINGE, SLIDER, CONE_TWIST, SPRING_JOINT = range(6)
FRAME = -1  # body_b of a joint to the world or an animated object


@dataclass(frozen=True)
class JointSettings:
    """One joint (see the module docstring).

    Attributes:
        name: what messages call it (the constraint's object).
        kind: one of :data:`JOINT_KINDS`.
        body_a: the body index of side A. body_b: side B's, or FRAME (the world, or an animated
            object whose frames the caller gives per frame).
        matrix: (4, 4) world frame at the start: pivot (translation) and axes (rotation
            columns; a scale is taken out).
        use_limits, lower, upper: HINGE angle [rad] and SLIDER distance [m] within
            [lower, upper]; CONE_TWIST twist [rad] within them. cone: CONE_TWIST's swing
            limit [rad] (always on), in (0, pi).
        use_motor, motor_velocity, motor_max: HINGE [rad/s], [N m] and SLIDER [m/s], [N]: drives
            B relative to A at the velocity with at most that torque / force.
        use_spring, stiffness, damping: HINGE [N m/rad], [N m s/rad] and SLIDER [N/m],
            [N s/m]: a damped spring towards angle / distance 0 (the start); SPRING's own
            [N/m], [N s/m] (always on).
        break_force: [N] the joint breaks above it (inf: never).
        disable_collisions: the two bodies do not collide with each other.
    """

    name: str
    kind: str
    body_a: int
    body_b: int = FRAME
    matrix: np.ndarray = field(default_factory=lambda: np.eye(4))
    use_limits: bool = False
    lower: float = 0.0
    upper: float = 0.0
    cone: float = math.pi / 4
    use_motor: bool = False
    motor_velocity: float = 0.0
    motor_max: float = 0.0
    use_spring: bool = False
    stiffness: float = 0.0
    damping: float = 0.0
    break_force: float = math.inf
    disable_collisions: bool = True

    def __post_init__(self):
        def fail(message: str):
            raise PhysanimError(message, obj=self.name, kind="constraint")

        if self.kind not in JOINT_KINDS:
            fail(f"unknown type {self.kind!r}; choose one of {', '.join(JOINT_KINDS)}")
        if int(self.body_a) < 0 or (self.body_b != FRAME and int(self.body_b) < 0):
            fail(f"bodies must be indices (got {self.body_a}, {self.body_b})")
        if self.body_a == self.body_b:
            fail("it joins a body to itself — choose two different objects")
        m = np.asarray(self.matrix, dtype=np.float64)
        if m.shape != (4, 4) or not np.isfinite(m).all():
            fail("its matrix must be a finite 4x4 matrix")
        for key in ("lower", "upper", "motor_velocity"):
            if not math.isfinite(getattr(self, key)):
                fail(f"{key} must be finite (got {getattr(self, key)})")
        for key in ("motor_max", "stiffness", "damping"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value >= 0.0):
                fail(f"{key} must be finite and >= 0 (got {value})")
        if self.use_limits and self.lower > self.upper:
            fail(f"the lower limit {self.lower:g} is above the upper {self.upper:g}")
        if self.kind == "SPRING" and not (self.stiffness > 0.0 or self.damping > 0.0):
            fail("a spring needs a stiffness or a damping above 0")
        if self.kind == "CONE_TWIST" and not 0.0 < self.cone < math.pi:
            fail(f"the cone angle must be in (0, pi) rad (got {self.cone})")
        if not (self.break_force > 0.0) or math.isnan(self.break_force):
            fail(f"the breaking force must be > 0 (got {self.break_force})")


@dataclass(frozen=True)
class JointModel:
    """The joints of a run, (J, ...) each.

    Attributes:
        joint_name: names. joint_kind: codes (:data:`JOINT_KINDS` order).
        joint_a, joint_b: body indices (joint_b FRAME: a frame).
        joint_local_a, joint_local_b: (J, 4, 4) the joint's frame in each body's frame (its
            centre of mass and axes); for a FRAME side, its world frame at the start.
        joint_use_limits, joint_lower, joint_upper, joint_cone, joint_use_motor,
        joint_motor_velocity, joint_motor_max, joint_use_spring, joint_stiffness,
        joint_damping, joint_break_force, joint_disable_collisions: the settings.
    """

    joint_name: tuple = ()
    joint_kind: np.ndarray = field(default_factory=lambda: frozen([], np.int8))
    joint_a: np.ndarray = field(default_factory=lambda: frozen([], np.int64))
    joint_b: np.ndarray = field(default_factory=lambda: frozen([], np.int64))
    joint_local_a: np.ndarray = field(default_factory=lambda: frozen(np.zeros((0, 4, 4))))
    joint_local_b: np.ndarray = field(default_factory=lambda: frozen(np.zeros((0, 4, 4))))
    joint_use_limits: np.ndarray = field(default_factory=lambda: frozen([], bool))
    joint_lower: np.ndarray = field(default_factory=lambda: frozen([]))
    joint_upper: np.ndarray = field(default_factory=lambda: frozen([]))
    joint_cone: np.ndarray = field(default_factory=lambda: frozen([]))
    joint_use_motor: np.ndarray = field(default_factory=lambda: frozen([], bool))
    joint_motor_velocity: np.ndarray = field(default_factory=lambda: frozen([]))
    joint_motor_max: np.ndarray = field(default_factory=lambda: frozen([]))
    joint_use_spring: np.ndarray = field(default_factory=lambda: frozen([], bool))
    joint_stiffness: np.ndarray = field(default_factory=lambda: frozen([]))
    joint_damping: np.ndarray = field(default_factory=lambda: frozen([]))
    joint_break_force: np.ndarray = field(default_factory=lambda: frozen([]))
    joint_disable_collisions: np.ndarray = field(default_factory=lambda: frozen([], bool))

    @property
    def joint_count(self) -> int:
        return len(self.joint_name)

    def state(self) -> JointState:
        return JointState(np.zeros((self.joint_count, ROWS)), np.zeros(self.joint_count, bool),
                          np.full(self.joint_count, -1, np.int64))

    def with_values(self, joints: list[JointSettings]) -> JointModel:
        """These joints with the animatable values (:data:`VALUES`: limits, motor, spring,
        breaking) of ``joints`` (one settings per joint, same order: the values a frame
        keyed); their structure (kinds, bodies, frames) stays."""
        if len(joints) != self.joint_count:
            raise ValueError(f"{len(joints)} joint settings for {self.joint_count} joints")
        for s, name, kind in zip(joints, self.joint_name, self.joint_kind):
            if s.name != name or JOINT_KINDS.index(s.kind) != kind:
                raise PhysanimError("its type changed during the bake (it is read at the first "
                                    "frame)", obj=name, kind="constraint")
        return replace(self, **{f"joint_{key}": _column(joints, key, dtype)
                                for key, dtype in VALUES.items()})

    def excluded_pairs(self, body_count: int) -> np.ndarray:
        """Keys lo * body_count + hi of the body pairs that must not collide."""
        both = self.joint_disable_collisions & (self.joint_b != FRAME)
        a, b = self.joint_a[both], self.joint_b[both]
        return np.unique(np.minimum(a, b) * body_count + np.maximum(a, b))


# the settings an animator may key, read every frame (JointModel.with_values), and their types
VALUES = {"use_limits": bool, "lower": np.float64, "upper": np.float64, "cone": np.float64,
          "use_motor": bool, "motor_velocity": np.float64, "motor_max": np.float64,
          "use_spring": bool, "stiffness": np.float64, "damping": np.float64,
          "break_force": np.float64}

ROWS = 10  # impulses kept per joint: 6 equality rows, then 4 limit / motor / spring rows


@dataclass
class JointState:
    """joint_impulse: (J, ROWS) accumulated impulses (warm starting); joint_broken: (J,);
    joint_broken_frame: (J,) the frame each broke at (-1: holds)."""

    joint_impulse: np.ndarray
    joint_broken: np.ndarray
    joint_broken_frame: np.ndarray


def joint_model(joints: list[JointSettings], body_x: np.ndarray, body_q_matrix: np.ndarray
                ) -> JointModel:
    """Freeze ``joints`` for bodies whose centres of mass are at ``body_x`` (n, 3) with axes
    ``body_q_matrix`` (n, 3, 3) at the start."""
    n = len(body_x)
    for s in joints:
        if s.body_a >= n or s.body_b >= n:
            raise PhysanimError(f"it names body {max(s.body_a, s.body_b)} of {n}", obj=s.name,
                                kind="constraint")
    world = np.array([_unscaled(s.matrix) for s in joints]).reshape(-1, 4, 4)

    def local(bodies: np.ndarray) -> np.ndarray:
        out = world.copy()
        on = bodies != FRAME
        body = np.zeros((int(on.sum()), 4, 4))
        body[:, :3, :3] = body_q_matrix[bodies[on]]
        body[:, :3, 3] = body_x[bodies[on]]
        body[:, 3, 3] = 1.0
        out[on] = np.linalg.inv(body) @ world[on]
        return out

    a = np.array([s.body_a for s in joints], np.int64)
    b = np.array([s.body_b for s in joints], np.int64)

    def column(key, dtype=np.float64):
        return _column(joints, key, dtype)

    return JointModel(
        tuple(s.name for s in joints), frozen([JOINT_KINDS.index(s.kind) for s in joints],
                                              np.int8),
        frozen(a, np.int64), frozen(b, np.int64), frozen(local(a)), frozen(local(b)),
        column("use_limits", bool), column("lower"), column("upper"), column("cone"),
        column("use_motor", bool), column("motor_velocity"), column("motor_max"),
        column("use_spring", bool), column("stiffness"), column("damping"),
        column("break_force"), column("disable_collisions", bool))


def _column(joints: list[JointSettings], key: str, dtype=np.float64) -> np.ndarray:
    return frozen([getattr(s, key) for s in joints], dtype)


def _unscaled(m) -> np.ndarray:
    """``m`` (4, 4) with its axes normalised (a scaled Empty places a joint, not a size)."""
    m = np.array(m, dtype=np.float64)
    m[:3, :3] /= np.linalg.norm(m[:3, :3], axis=0)
    return m
