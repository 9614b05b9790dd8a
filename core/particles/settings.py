"""Frozen settings of particle emitters, validated on construction.

Static settings (:class:`EmitterSettings`) go into the Model once; the values an animator may
keyframe (:class:`EmitterFrame`, collider and force frames) are sampled per frame by the caller
and handed to the solver for that frame. Units: SI, seconds, radians.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..curves import LifeCurve
from ..validate import finite, is_finite, matrix, non_negative

SOURCES = ("ORIGIN", "VERTS", "FACES", "VOLUME", "DEATHS")
DIRECTIONS = ("NORMAL", "AXIS", "RANDOM")
LIMIT_BIRTHS_PER_FRAME = 10_000_000


@dataclass(frozen=True)
class SpringLink:
    """Damped springs joining each particle to the previous one born by the same emitter.

    Args:
        stiffness: ks [N/m]. damping: kd [N s/m]. rest_length: r [m]; negative means "the
        distance at birth".
        hard: rods of fixed length r instead (hard constraints: a rope that never stretches;
        stiffness and damping unused).
    """

    stiffness: float
    damping: float
    rest_length: float = -1.0
    hard: bool = False

    def __post_init__(self):
        non_negative("particle springs", stiffness=self.stiffness, damping=self.damping)
        finite("particle springs", rest_length=self.rest_length)


@dataclass(frozen=True)
class EmitterSettings:
    """What never changes during a bake.

    Args:
        name: the emitter's name (used in every message).
        source: where particles are born: ``ORIGIN`` (object origin), ``VERTS``, ``FACES``
            (area-weighted), ``VOLUME`` (inside a closed mesh) or ``DEATHS`` (where particles of
            emitter ``parent`` die: sub-emitter bursts, rate = births per death).
        direction: ``NORMAL`` (surface normal; local ``axis`` at the origin; the dying particle's
            velocity for ``DEATHS``), ``AXIS`` (local ``axis``) or ``RANDOM`` (uniform sphere).
        axis: local direction for ``AXIS`` and the origin's normal.
        seed: this emitter's seed, combined with the scene seed and a hash of ``name`` (not the
            emitter's index, so other emitters never change this one's particles).
        triangles: (m, 3) vertex indices of the source mesh's triangles (``FACES``/``VOLUME``).
        vertex_count: number of vertices of the source mesh.
        color: RGBA over life fraction (alpha = 1 - transparency).
        size: size factor over life fraction.
        stretch: shape from velocity: instances scale along their velocity by 1 + stretch*|v|
            [s/m]; 0 keeps them round and unrotated.
        link: optional springs joining consecutive particles (a chain).
        even: births evenly spaced in time within each frame interval instead of at random
            times (a moving emitter lays them out evenly: a rope's particles).
    """

    name: str
    source: str = "ORIGIN"
    direction: str = "NORMAL"
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    seed: int = 0
    parent: int | None = None
    triangles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))
    vertex_count: int = 0
    color: LifeCurve = field(default_factory=lambda: LifeCurve.constant(1.0, 1.0, 1.0, 1.0))
    size: LifeCurve = field(default_factory=lambda: LifeCurve.constant(1.0))
    stretch: float = 0.0
    link: SpringLink | None = None
    even: bool = False

    def __post_init__(self):
        owner = f'emitter "{self.name}"'
        if self.source not in SOURCES:
            raise ValueError(f"{owner}: source must be one of {SOURCES} (got {self.source!r})")
        if self.direction not in DIRECTIONS:
            raise ValueError(f"{owner}: direction must be one of {DIRECTIONS} (got {self.direction!r})")
        if (self.source == "DEATHS") != (self.parent is not None):
            raise ValueError(f"{owner}: a parent emitter is needed exactly when source is DEATHS")
        axis = np.asarray(self.axis, dtype=np.float64)
        if axis.shape != (3,) or not np.all(np.isfinite(axis)) or np.linalg.norm(axis) == 0.0:
            raise ValueError(f"{owner}: axis must be a non-zero 3-vector (got {self.axis})")
        tris = np.asarray(self.triangles, dtype=np.int64).reshape(-1, 3)
        tris.setflags(write=False)
        object.__setattr__(self, "triangles", tris)
        if len(tris) and (tris.min() < 0 or tris.max() >= self.vertex_count):
            raise ValueError(f"{owner}: triangle indices out of range 0..{self.vertex_count - 1}")
        if self.color.channels != 4:
            raise ValueError(f"{owner}: color curve needs RGBA values (got {self.color.channels})")
        if self.size.channels != 1:
            raise ValueError(f"{owner}: size curve needs one value per stop")
        non_negative(owner, stretch=self.stretch)


POINT_CONSTRAINTS = ("ON_PLANE", "ON_SPHERE", "ON_CIRCLE", "ON_CURVE", "TIE")


@dataclass(frozen=True)
class PointConstraint:
    """A hard constraint on every particle of one emitter over a frame interval, placed by a
    frame that moves from ``matrix0`` to ``matrix1`` (its origin o and z axis n):

        ON_PLANE   on the plane through o with normal n
        ON_SPHERE  at ``radius`` from o (on a sphere; a pendulum's rod to a pivot)
        ON_CIRCLE  on the circle of ``radius`` about o in that plane (a bead on a wire)
        ON_CURVE   on the polyline through ``points0`` at the start, ``points1`` at the end
                   (world positions, vertex by vertex; closed when ``cyclic``): a bead on a
                   wire of any shape (:class:`~..forces.OnCurves`)
        TIE        the particles within ``radius`` of o when first seen stay where they are
                   on the ``target`` object (its frames ``target0`` .. ``target1``; the world
                   when it has no name): a rope's end tied to a hook. A target that is a
                   rigid body simulated in the same world is pulled by the particles and
                   swings them (two-way: :mod:`.ties`)

    Args: name: what messages call it (the constraint's object). kind: one of
    :data:`POINT_CONSTRAINTS`. matrix0, matrix1: (4, 4) world matrices. radius [m].
    points0, points1: (P, 3) [m], ON_CURVE only. cyclic: ON_CURVE only. target: the
    object a TIE holds its particles on ("": the world); target0, target1: its (4, 4) world
    matrices at the interval's ends (unused for a rigid body of the same world, whose path
    the world gives).
    """

    name: str
    kind: str
    matrix0: np.ndarray = field(default_factory=lambda: np.eye(4))
    matrix1: np.ndarray = field(default_factory=lambda: np.eye(4))
    radius: float = 1.0
    points0: np.ndarray | None = None
    points1: np.ndarray | None = None
    cyclic: bool = False
    target: str = ""
    target0: np.ndarray = field(default_factory=lambda: np.eye(4))
    target1: np.ndarray = field(default_factory=lambda: np.eye(4))

    def __post_init__(self):
        owner = f'constraint "{self.name}"'
        if self.kind == "ON_CURVE":
            self._check_curve(owner)
        if self.kind not in POINT_CONSTRAINTS:
            raise ValueError(f"{owner}: kind must be one of {POINT_CONSTRAINTS} (got {self.kind!r})")
        for key in ("matrix0", "matrix1", "target0", "target1"):
            object.__setattr__(self, key, matrix(owner, key, getattr(self, key)))
            if np.linalg.norm(getattr(self, key)[:3, 2]) < 1e-12:
                raise ValueError(f"{owner}: its Z axis has zero length (a zero scale)")
        finite(owner, radius=self.radius)
        if self.kind in ("ON_SPHERE", "ON_CIRCLE", "TIE") and not self.radius > 0.0:
            raise ValueError(f"{owner}: the radius must be > 0 (got {self.radius})")
        if self.kind == "TIE" and min(abs(np.linalg.det(m[:3, :3]))
                                      for m in (self.target0, self.target1)) < 1e-12:
            raise ValueError(f'{owner}: the object it ties to ("{self.target}") has a zero '
                             "scale — give it a scale")

    def _check_curve(self, owner: str) -> None:
        """A wire's points: two (P, 3) finite arrays of the same shape, P >= 2, no two
        neighbours at one place."""
        if self.points0 is None or self.points1 is None:
            raise ValueError(f"{owner}: a wire of any shape needs its points at both ends of "
                             "the interval")
        for key in ("points0", "points1"):
            pts = np.asarray(getattr(self, key), np.float64)
            if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 2:
                raise ValueError(f"{owner}: the wire needs at least two points (got an array "
                                 f"of shape {pts.shape})")
            if not np.all(np.isfinite(pts)):
                raise ValueError(f"{owner}: the wire's points must be finite")
            gaps = np.linalg.norm(np.diff(np.vstack([pts, pts[:1]]) if self.cyclic else pts,
                                          axis=0), axis=1)
            if np.any(gaps <= 0.0):
                k = int(np.argmax(gaps <= 0.0))
                raise ValueError(f"{owner}: the wire's points {k} and {(k + 1) % len(pts)} are "
                                 "at the same place")
            object.__setattr__(self, key, pts)
        if self.points0.shape != self.points1.shape:
            raise ValueError(f"{owner}: the wire changed its number of points from "
                             f"{len(self.points0)} to {len(self.points1)} within a frame")


@dataclass(frozen=True)
class EmitterFrame:
    """Keyframable emitter values for one frame interval [t, t + frame_dt], plus its motion.

    Births per frame = ``rate + Rand()*rate_random`` with Rand uniform in [-1, 1], rounded
    stochastically (so the mean is exact); each birth gets a uniform sub-frame time.

    Args:
        rate: mean births per frame (per death for ``DEATHS``). rate_random: r.
        speed, speed_random: initial speed [m/s] +- uniform random. ``speed_random`` may exceed
            ``speed`` on purpose: a negative draw launches the particle backwards (against its
            direction), which is how a symmetric spray along an axis is made.
        lifetime, lifetime_random: life span [s] +- uniform random; ``lifetime_random`` must not
            exceed ``lifetime`` (a life span cannot be negative).
        mass: [kg]. size: base size [m] +- ``size_random`` [m], which must not exceed ``size``.
        spread: cone half-angle around the direction [rad].
        inherit_velocity: factor of the emitter's velocity at the birth point (robot-arm throw).
        launch: (3,) world velocity added to every birth [m/s] (Hit the Mark solves it).
        active: whether this emitter gives births in this frame interval.
        matrix0, matrix1: (4, 4) world matrices at the start and end of the interval.
        matrices: optional (k + 1, 4, 4) sub-frame samples at s = 0, 1/k, ..., 1 (curved motion).
        verts0, verts1: (n, 3) local vertex positions at start and end (None for ``ORIGIN``).
        constraints: hard constraints on this emitter's particles (:class:`PointConstraint`).
    """

    rate: float = 10.0
    rate_random: float = 0.0
    speed: float = 1.0
    speed_random: float = 0.0
    lifetime: float = 2.0
    lifetime_random: float = 0.0
    mass: float = 1.0
    size: float = 0.05
    size_random: float = 0.0
    spread: float = 0.0
    inherit_velocity: float = 0.0
    launch: tuple[float, float, float] = (0.0, 0.0, 0.0)
    active: bool = True
    matrix0: np.ndarray = field(default_factory=lambda: np.eye(4))
    matrix1: np.ndarray = field(default_factory=lambda: np.eye(4))
    matrices: np.ndarray | None = None
    verts0: np.ndarray | None = None
    verts1: np.ndarray | None = None
    constraints: tuple = ()

    def validated(self, name: str) -> EmitterFrame:
        """This frame's values, checked (a ValueError naming the emitter and the value)."""
        if not self._plainly_valid():
            self._check(name)
        return self

    def _plainly_valid(self) -> bool:
        """Whether every check of :meth:`_check` passes, found in one expression: a bake asks
        every frame for every emitter (the checks one by one cost a frame of 10,000 particles
        a twentieth of its time). False may still be valid (a sum of finite values that
        overflows): :meth:`_check` tells, naming what is wrong."""
        inf = math.inf
        launch = self.launch
        return (0.0 <= self.rate < inf and 0.0 <= self.rate_random < inf and
                0.0 <= self.speed < inf and 0.0 <= self.speed_random < inf and
                0.0 <= self.lifetime_random <= self.lifetime < inf and
                0.0 <= self.size_random <= self.size < inf and 0.0 <= self.spread < inf and
                is_finite(self.inherit_velocity) and self.mass > 0.0 and
                is_finite(self.mass) and self.rate + self.rate_random <=
                LIMIT_BIRTHS_PER_FRAME and len(launch) == 3 and is_finite(launch[0]) and
                is_finite(launch[1]) and is_finite(launch[2]) and
                _finite(self.matrix0, (4, 4)) and _finite(self.matrix1, (4, 4)) and
                (self.matrices is None or _finite(self.matrices, (len(self.matrices), 4, 4)))
                and (self.verts0 is None or _finite(self.verts0)) and
                (self.verts1 is None or _finite(self.verts1)))

    def _check(self, name: str) -> None:
        owner = f'emitter "{name}"'
        non_negative(owner, rate=self.rate, rate_random=self.rate_random, speed=self.speed,
                      speed_random=self.speed_random, lifetime=self.lifetime,
                      lifetime_random=self.lifetime_random, size=self.size,
                      size_random=self.size_random, spread=self.spread)
        finite(owner, inherit_velocity=self.inherit_velocity)
        if len(self.launch) != 3 or not all(is_finite(v) for v in self.launch):
            raise ValueError(f"{owner}: launch velocity must be 3 finite numbers (got "
                             f"{tuple(self.launch)})")
        # +- random must not cross zero: a negative life span or size has no meaning, and
        # clamping it would silently change the distribution the user asked for.
        if self.lifetime_random > self.lifetime:
            raise ValueError(f"{owner}: lifetime_random {self.lifetime_random:g} s is larger than "
                             f"lifetime {self.lifetime:g} s: life spans would become negative — "
                             "lower lifetime_random or raise lifetime")
        if self.size_random > self.size:
            raise ValueError(f"{owner}: size_random {self.size_random:g} is larger than size "
                             f"{self.size:g}: sizes would become negative — lower size_random or "
                             "raise size")
        if not (self.mass > 0.0 and is_finite(self.mass)):
            raise ValueError(f"{owner}: mass must be > 0 (got {self.mass})")
        if self.rate + self.rate_random > LIMIT_BIRTHS_PER_FRAME:
            raise ValueError(f"{owner}: rate + rate_random may be at most "
                             f"{LIMIT_BIRTHS_PER_FRAME} per frame (got {self.rate + self.rate_random})")
        matrix(owner, "matrix0", self.matrix0)
        matrix(owner, "matrix1", self.matrix1)
        if self.matrices is not None:
            for k, m in enumerate(self.matrices):
                matrix(owner, f"sub-frame matrix {k}", m)
        for key in ("verts0", "verts1"):
            v = getattr(self, key)
            if v is not None and not np.all(np.isfinite(v)):
                bad = np.argwhere(~np.isfinite(np.asarray(v)))[0][0]
                raise ValueError(f"{owner}: vertex {bad} has a non-finite position")


_ZEROS = np.zeros(16)
_ZEROS.flags.writeable = False


def _finite(a, shape: tuple | None = None) -> bool:
    """Whether ``a`` is a float array (of ``shape``) of finite values: a matrix (float64, as
    the full check reads it) by one product with zeros (0 exactly for finite values, NaN for
    a NaN or an infinity, never an overflow or a warning), vertices by numpy's test."""
    if shape is None:
        return type(a) is np.ndarray and a.dtype.kind == "f" and bool(np.isfinite(a).all())
    if not (type(a) is np.ndarray and a.dtype == np.float64 and a.shape == shape):
        return False
    flat = a.ravel()
    return np.dot(flat, _ZEROS if len(flat) == 16 else np.zeros(len(flat))) == 0.0
