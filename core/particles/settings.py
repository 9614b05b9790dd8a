"""Frozen settings of particle emitters, colliders and forces, validated on construction.

Static settings (:class:`EmitterSettings`) go into the Model once; the values an animator may
keyframe (:class:`EmitterFrame`, collider and force frames) are sampled per frame by the caller
and handed to the solver for that frame. Units: SI, seconds, radians.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..curves import LifeCurve

SOURCES = ("ORIGIN", "VERTS", "FACES", "VOLUME", "DEATHS")
DIRECTIONS = ("NORMAL", "AXIS", "RANDOM")
COLLIDER_SHAPES = ("HALF_SPACE", "PLANE", "SPHERE", "BOX", "MESH")
LIMIT_BIRTHS_PER_FRAME = 10_000_000


def _finite(owner: str, **values: float) -> None:
    for key, value in values.items():
        if not math.isfinite(value):
            raise ValueError(f'{owner}: {key} must be finite (got {value})')


def _non_negative(owner: str, **values: float) -> None:
    _finite(owner, **values)
    for key, value in values.items():
        if value < 0.0:
            raise ValueError(f'{owner}: {key} must be >= 0 (got {value})')


def _matrix(owner: str, key: str, m) -> np.ndarray:
    m = np.asarray(m, dtype=np.float64)
    if m.shape != (4, 4):
        raise ValueError(f"{owner}: {key} must be a 4x4 matrix (got shape {m.shape})")
    if not np.all(np.isfinite(m)):
        raise ValueError(f"{owner}: {key} has non-finite entries")
    return m


@dataclass(frozen=True)
class SpringLink:
    """Damped springs joining each particle to the previous one born by the same emitter.

    Args:
        stiffness: ks [N/m]. damping: kd [N s/m]. rest_length: r [m]; negative means "the
        distance at birth".
    """

    stiffness: float
    damping: float
    rest_length: float = -1.0

    def __post_init__(self):
        _non_negative("particle springs", stiffness=self.stiffness, damping=self.damping)
        _finite("particle springs", rest_length=self.rest_length)


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
        _non_negative(owner, stretch=self.stretch)


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
        active: whether this emitter gives births in this frame interval.
        matrix0, matrix1: (4, 4) world matrices at the start and end of the interval.
        matrices: optional (k + 1, 4, 4) sub-frame samples at s = 0, 1/k, ..., 1 (curved motion).
        verts0, verts1: (n, 3) local vertex positions at start and end (None for ``ORIGIN``).
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
    active: bool = True
    matrix0: np.ndarray = field(default_factory=lambda: np.eye(4))
    matrix1: np.ndarray = field(default_factory=lambda: np.eye(4))
    matrices: np.ndarray | None = None
    verts0: np.ndarray | None = None
    verts1: np.ndarray | None = None

    def validated(self, name: str) -> EmitterFrame:
        owner = f'emitter "{name}"'
        _non_negative(owner, rate=self.rate, rate_random=self.rate_random, speed=self.speed,
                      speed_random=self.speed_random, lifetime=self.lifetime,
                      lifetime_random=self.lifetime_random, size=self.size,
                      size_random=self.size_random, spread=self.spread)
        _finite(owner, inherit_velocity=self.inherit_velocity)
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
        if not (self.mass > 0.0 and math.isfinite(self.mass)):
            raise ValueError(f"{owner}: mass must be > 0 (got {self.mass})")
        if self.rate + self.rate_random > LIMIT_BIRTHS_PER_FRAME:
            raise ValueError(f"{owner}: rate + rate_random may be at most "
                             f"{LIMIT_BIRTHS_PER_FRAME} per frame (got {self.rate + self.rate_random})")
        _matrix(owner, "matrix0", self.matrix0)
        _matrix(owner, "matrix1", self.matrix1)
        if self.matrices is not None:
            for k, m in enumerate(self.matrices):
                _matrix(owner, f"sub-frame matrix {k}", m)
        for key in ("verts0", "verts1"):
            v = getattr(self, key)
            if v is not None and not np.all(np.isfinite(v)):
                bad = np.argwhere(~np.isfinite(np.asarray(v)))[0][0]
                raise ValueError(f"{owner}: vertex {bad} has a non-finite position")
        return self


@dataclass(frozen=True)
class ColliderFrame:
    """A collider during one frame interval.

    Shapes live in the object's local space: ``HALF_SPACE`` is z <= 0 (an infinite ground),
    ``PLANE`` the two-sided square |x|, |y| <= 1 at z = 0, ``SPHERE`` the unit sphere and ``BOX``
    the cube |x|, |y|, |z| <= 1 — Blender's default primitives — mapped by the world matrix.
    ``MESH`` is any triangle mesh (open, single-sided ones too: both faces collide), whose local
    vertices may move during the interval (a deforming mesh), mapped by the same world matrix.

    Args:
        name: object name for messages.
        shape: one of :data:`COLLIDER_SHAPES`.
        matrix0, matrix1: (4, 4) world matrices at the interval's start and end.
        matrices: optional (k + 1, 4, 4) sub-frame samples at s = 0, 1/k, ..., 1.
        restitution: k_r in [0, 1]: normal speed kept after a bounce.
        friction: Coulomb coefficient mu >= 0.
        thickness: the surface is grown outwards by this much [m] (a particle's radius, a
            cloth's half-thickness), so points stop that far from the shape.
        vertices0, vertices1: ``MESH`` only: (n, 3) local vertex positions [m] at the interval's
            start and end (equal for a mesh that does not deform); positions in between are
            interpolated linearly.
        triangles: ``MESH`` only: (m, 3) vertex indices (the winding gives the face normals).
    """

    name: str
    shape: str
    matrix0: np.ndarray
    matrix1: np.ndarray
    restitution: float = 0.5
    friction: float = 0.2
    matrices: np.ndarray | None = None
    thickness: float = 0.0
    vertices0: np.ndarray | None = None
    vertices1: np.ndarray | None = None
    triangles: np.ndarray | None = None

    def __post_init__(self):
        owner = f'collider "{self.name}"'
        _non_negative(owner, thickness=self.thickness)
        if self.shape not in COLLIDER_SHAPES:
            raise ValueError(f"{owner}: shape must be one of {COLLIDER_SHAPES} (got {self.shape!r})")
        _non_negative(owner, restitution=self.restitution, friction=self.friction)
        if self.restitution > 1.0:
            raise ValueError(f"{owner}: restitution must be <= 1 (got {self.restitution})")
        for key in ("matrix0", "matrix1"):
            m = _matrix(owner, key, getattr(self, key))
            if abs(np.linalg.det(m[:3, :3])) < 1e-12:
                raise ValueError(f"{owner}: {key} is singular (a zero scale flattens the collider)")
            object.__setattr__(self, key, m)
        if self.matrices is not None:
            for k, m in enumerate(self.matrices):
                if abs(np.linalg.det(_matrix(owner, f"sub-frame matrix {k}", m)[:3, :3])) < 1e-12:
                    raise ValueError(f"{owner}: sub-frame matrix {k} is singular (zero scale)")
        if self.shape == "MESH":
            self._validate_mesh(owner)
        elif any(getattr(self, k) is not None for k in ("vertices0", "vertices1", "triangles")):
            raise ValueError(f"{owner}: vertices and triangles are for MESH colliders only "
                             f"(shape is {self.shape})")

    def _validate_mesh(self, owner: str) -> None:
        verts = []
        for key in ("vertices0", "vertices1"):
            if getattr(self, key) is None:
                raise ValueError(f"{owner}: a MESH collider needs {key}")
            v = np.array(getattr(self, key), dtype=np.float64)
            if v.ndim != 2 or v.shape[1] != 3:
                raise ValueError(f"{owner}: {key} must be an (n, 3) array (got shape {v.shape})")
            bad = ~np.isfinite(v).all(axis=1)
            if bad.any():
                i = int(np.argmax(bad))
                raise ValueError(f"{owner}: {key} vertex {i} is not finite: {v[i].tolist()}")
            v.setflags(write=False)
            object.__setattr__(self, key, v)
            verts.append(v)
        if len(verts[0]) != len(verts[1]):
            raise ValueError(f"{owner}: vertices0 has {len(verts[0])} vertices but vertices1 has "
                             f"{len(verts[1])}: a deforming mesh must keep its vertex count")
        if self.triangles is None:
            raise ValueError(f"{owner}: a MESH collider needs triangles")
        t = np.asarray(self.triangles)
        if t.size == 0:
            raise ValueError(f"{owner}: the mesh has no triangles to collide with")
        if t.ndim != 2 or t.shape[1] != 3 or t.dtype.kind not in "iu":
            raise ValueError(f"{owner}: triangles must be an (m, 3) integer array "
                             f"(got shape {t.shape}, dtype {t.dtype})")
        t = t.astype(np.int64)
        out = (t < 0) | (t >= len(verts[0]))
        if out.any():
            i = int(np.argmax(out.any(axis=1)))
            raise ValueError(f"{owner}: triangle {i} refers to vertex {t[i].tolist()} but the "
                             f"mesh has {len(verts[0])} vertices")
        t.setflags(write=False)
        object.__setattr__(self, "triangles", t)
