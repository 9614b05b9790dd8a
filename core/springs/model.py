"""Spring-mesh Model (built once from a rest mesh) and State.

Every vertex is a point mass; springs come in families (structural edges, shear diagonals,
bending) with their own stiffness and damping; vertices may be pinned (hard, weight >= 0.999,
following their animated rest position) or softly held (zero-rest-length virtual springs,
stiffness scaled by the vertex-group weight); virtual springs may attach a vertex group to
another object or keep it a distance away from one.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import PhysanimError
from . import topology

BEND_MODES = ("ANGULAR", "DISTANCE", "NONE")
MASS_MODES = ("EVEN", "AREA")
VIRTUAL_MODES = ("PIN", "ATTACH", "DISTANCE")
HARD_PIN_WEIGHT = 0.999  # a pin-group weight at least this pins the vertex exactly


@dataclass(frozen=True)
class SpringMeshSettings:
    """Static settings of one spring mesh (SI units).

    Args:
        name: object name (for messages). mass: total mass [kg]. mass_mode: ``EVEN`` (as the
        seed: every vertex the same) or ``AREA`` (by the area around each vertex).
        stiffness, damping: structural (edge) springs [N/m], [N s/m].
        shear_stiffness, shear_damping: face-diagonal springs (0 = none).
        bend_mode: ``ANGULAR`` (dihedral spring-dampers about each shared edge), ``DISTANCE``
        (springs between the wing vertices of each shared edge) or ``NONE``.
        bend_stiffness, bend_damping: [N m/rad], [N m s/rad] for ANGULAR, [N/m], [N s/m] else.
        drag: viscous air drag per unit mass [1/s]. pin_stiffness: [N/m] of soft pins (weight
        below 1 scales it). max_stretch: strain limit of edge and shear springs (0.1 = they
        never stretch past 110 %; 0 = no limit), Provot's deformation constraints.
        self_collision: keep the mesh off itself (:mod:`.self_collision`). self_distance:
        kept between its vertices and triangles, edges and edges [m]. self_friction: Coulomb
        mu between its layers. sleep: the mesh stops being simulated while it is at rest
        and nothing around it changes (:mod:`.sleep`).
    """

    name: str
    mass: float = 1.0
    mass_mode: str = "EVEN"
    stiffness: float = 1000.0
    damping: float = 1.0
    shear_stiffness: float = 500.0
    shear_damping: float = 0.5
    bend_mode: str = "ANGULAR"
    bend_stiffness: float = 0.05
    bend_damping: float = 0.001
    drag: float = 0.1
    pin_stiffness: float = 1000.0
    max_stretch: float = 0.0
    self_collision: bool = False
    self_distance: float = 0.01
    self_friction: float = 0.2
    sleep: bool = True

    def __post_init__(self):
        owner = f'spring mesh "{self.name}"'
        if self.mass_mode not in MASS_MODES:
            raise ValueError(f"{owner}: mass_mode must be one of {MASS_MODES} (got {self.mass_mode!r})")
        if self.bend_mode not in BEND_MODES:
            raise ValueError(f"{owner}: bend_mode must be one of {BEND_MODES} (got {self.bend_mode!r})")
        if not (math.isfinite(self.mass) and self.mass > 0.0):
            raise ValueError(f"{owner}: mass must be > 0 kg (got {self.mass})")
        for key in ("stiffness", "damping", "shear_stiffness", "shear_damping", "bend_stiffness",
                    "bend_damping", "drag", "pin_stiffness", "max_stretch", "self_friction"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{owner}: {key} must be finite and >= 0 (got {value})")
        if not (math.isfinite(self.self_distance) and self.self_distance > 0.0):
            raise ValueError(f"{owner}: self_distance must be > 0 m (got {self.self_distance})")


@dataclass(frozen=True)
class VirtualSprings:
    """A group of virtual springs.

    ``PIN``: each vertex to its own animated rest position (zero rest length).
    ``ATTACH``: each vertex to the point of another object it sat on at the start (follows that
    object's animation rigidly; zero rest length). ``DISTANCE``: each vertex kept ``rest_length``
    from another object's origin.

    Args: mode; index: (s,) vertices; weight: (s,) in (0, 1] scaling the stiffness and damping;
    rest_length [m]; stiffness [N/m]; damping [N s/m]; target: object name (ATTACH/DISTANCE).
    """

    mode: str
    index: np.ndarray
    weight: np.ndarray
    rest_length: float = 0.0
    stiffness: float = 100.0
    damping: float = 1.0
    target: str | None = None

    def __post_init__(self):
        if self.mode not in VIRTUAL_MODES:
            raise ValueError(f"virtual springs: mode must be one of {VIRTUAL_MODES} (got {self.mode!r})")
        if (self.mode == "PIN") != (self.target is None):
            raise ValueError(f"virtual springs: a {self.mode} spring group "
                             f"{'needs no' if self.mode == 'PIN' else 'needs a'} target object")
        for key in ("rest_length", "stiffness", "damping"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"virtual springs: {key} must be finite and >= 0 (got {value})")


@dataclass(frozen=True)
class Attachment:
    """Vertices held rigidly on the points of another object where they sat at the first frame
    (a hard constraint: they move exactly with it). When the object is a body another system
    simulates (a rigid body), the impulses that hold the vertices go back to it: the mesh pulls
    the body as the body carries the mesh (two-way coupling, :mod:`..world`).

    Args: index: (k,) vertices. target: the object's name; None holds them where they are in
    the world. collide: whether the mesh still collides with the target (off: a cloth sewn
    onto a body passes through it, as a joint's "disable collisions").
    """

    index: np.ndarray
    target: str | None = None
    collide: bool = True

    def __post_init__(self):
        index = np.atleast_1d(np.asarray(self.index, np.int64))
        if index.ndim != 1 or len(index) == 0:
            raise ValueError(f"an attachment needs vertices (got {index.shape})")
        object.__setattr__(self, "index", index)


@dataclass(frozen=True)
class SpringMeshModel:
    """Frozen arrays of a spring mesh.

    Attributes:
        settings: the settings. rest_x: (n, 3) rest positions [m] (world, at the start frame).
        vertex_mass: (n,) [kg]. spring_i, spring_j, spring_rest, spring_stiffness,
        spring_damping, spring_family: (s,) every pair spring (0 edge, 1 shear, 2 distance-2).
        hinge: (h, 4) angular springs and hinge_rest (h,) [rad]. triangles: (m, 3).
        pinned: (n,) bool, hard pins. virtual: the virtual spring groups.
        attachments: vertices held on other objects (:class:`Attachment`).
    """

    settings: SpringMeshSettings
    rest_x: np.ndarray
    vertex_mass: np.ndarray
    spring_i: np.ndarray
    spring_j: np.ndarray
    spring_rest: np.ndarray
    spring_stiffness: np.ndarray
    spring_damping: np.ndarray
    spring_family: np.ndarray
    hinge: np.ndarray
    hinge_rest: np.ndarray
    triangles: np.ndarray
    pinned: np.ndarray
    virtual: tuple[VirtualSprings, ...] = field(default_factory=tuple)
    attachments: tuple[Attachment, ...] = field(default_factory=tuple)

    @property
    def vertex_count(self) -> int:
        return len(self.rest_x)

    @property
    def held(self) -> np.ndarray:
        """(n,) bool: vertices that do not move freely (pinned or attached)."""
        held = self.pinned.copy()
        for a in self.attachments:
            held[a.index] = True
        return held

    def state(self) -> SpringMeshState:
        return SpringMeshState(self.rest_x.copy(), np.zeros_like(self.rest_x),
                               [None] * len(self.virtual), [None] * len(self.attachments))


@dataclass
class SpringMeshState:
    """Time-varying: vertex positions x (n, 3) [m] and velocities v (n, 3) [m/s], world space.

    ``attached``: per virtual-spring group, for ATTACH groups the vertices' rest positions in
    the target's local space, bound by the first frame the state is advanced (None before, and
    for other modes). ``bound``: the same per :class:`Attachment`.
    """

    x: np.ndarray
    v: np.ndarray
    attached: list = field(default_factory=list)
    bound: list = field(default_factory=list)

    def pose(self) -> SpringMeshState:
        """A copy of the vertices now, for drawing (see :meth:`between`)."""
        return SpringMeshState(self.x.copy(), self.v.copy())

    @staticmethod
    def between(a: SpringMeshState, b: SpringMeshState, w: float) -> SpringMeshState:
        """The vertices at the fraction ``w`` of one sub-step from pose ``a`` to pose ``b``,
        on straight lines (the path a sub-step takes)."""
        if w >= 1.0:
            return b
        return SpringMeshState(a.x + w * (b.x - a.x), a.v + w * (b.v - a.v))


FAMILY_NAMES = ("edge", "shear", "bending (distance-2)")


class SpringMeshBuilder:
    """Builds the spring families of a mesh and freezes them into a :class:`SpringMeshModel`.

    Args:
        settings: static settings.
        rest_x: (n, 3) rest positions [m].
        edges: (e, 2) vertex pairs. triangles: (m, 3) (for bending, area and volume).
        loop_start, loop_total, loop_vertices: polygons (for shear diagonals); may be empty.
        pin_weight: (n,) pin vertex-group weights in [0, 1] (None = nothing pinned).
    """

    def __init__(self, settings: SpringMeshSettings, rest_x, edges, triangles,
                 loop_start=(), loop_total=(), loop_vertices=(), pin_weight=None):
        self.settings = settings
        self.rest_x = np.ascontiguousarray(rest_x, dtype=np.float64).reshape(-1, 3)
        self.edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        self.triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        self.loops = tuple(np.asarray(a, dtype=np.int64) for a in (loop_start, loop_total, loop_vertices))
        self.pin_weight = None if pin_weight is None else np.asarray(pin_weight, dtype=np.float64)
        self.virtual: list[VirtualSprings] = []
        self.attachments: list[Attachment] = []

    def add_virtual(self, springs: VirtualSprings) -> int:
        self.virtual.append(springs)
        return len(self.virtual) - 1

    def add_attachment(self, attachment: Attachment) -> int:
        self.attachments.append(attachment)
        return len(self.attachments) - 1

    def _fail(self, message: str, frame):
        raise PhysanimError(message, obj=self.settings.name, frame=frame, kind="spring mesh")

    def finalize(self, frame: int | None = None) -> SpringMeshModel:
        s = self.settings
        x = self.rest_x
        n = len(x)
        if n == 0:
            self._fail("the mesh has no vertices", frame)
        if not np.all(np.isfinite(x)):
            bad = int(np.argwhere(~np.isfinite(x))[0][0])
            self._fail(f"vertex {bad} has a non-finite rest position {x[bad].tolist()}", frame)
        for name, arr in (("edges", self.edges), ("triangles", self.triangles)):
            if len(arr) and (arr.min() < 0 or arr.max() >= n):
                self._fail(f"{name} refer to vertices outside 0..{n - 1}", frame)
        pairs, families = [topology.unique_pairs(self.edges)], [0]
        if s.shear_stiffness > 0.0 and len(self.loops[0]):
            pairs.append(topology.polygon_diagonals(*self.loops))
            families.append(1)
        hinge = topology.hinges(self.triangles)
        hinge_rest = np.zeros(0)
        if s.bend_mode == "DISTANCE":
            pairs.append(topology.distance2_pairs(hinge))
            families.append(2)
        constants = {0: (s.stiffness, s.damping), 1: (s.shear_stiffness, s.shear_damping),
                     2: (s.bend_stiffness, s.bend_damping)}
        fam = np.concatenate([np.full(len(p), f, np.int8) for p, f in zip(pairs, families)])
        pairs = np.concatenate(pairs) if pairs else np.zeros((0, 2), np.int64)
        rest = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1)
        ks = np.array([constants[f][0] for f in range(3)])[fam]
        kd = np.array([constants[f][1] for f in range(3)])[fam]
        if s.bend_mode == "ANGULAR" and s.bend_stiffness + s.bend_damping > 0.0:
            hinge_rest = topology.dihedral_angles(x, hinge)
        else:
            hinge = np.zeros((0, 4), np.int64)
        mass = self._masses(frame)
        pinned = np.zeros(n, dtype=bool)
        if self.pin_weight is not None:
            if self.pin_weight.shape != (n,):
                self._fail(f"pin weights have shape {self.pin_weight.shape}, expected ({n},)", frame)
            pinned = self.pin_weight >= HARD_PIN_WEIGHT
        arrays = [x, mass, pairs[:, 0].copy(), pairs[:, 1].copy(), rest, ks, kd, fam, hinge,
                  hinge_rest, self.triangles, pinned]
        for a in arrays:
            a.setflags(write=False)
        for a in self.attachments:
            if a.index.min() < 0 or a.index.max() >= n:
                self._fail(f"an attachment to {a.target or 'the world'} refers to vertices "
                           f"outside 0..{n - 1}", frame)
        return SpringMeshModel(s, *arrays, virtual=tuple(self.virtual),
                               attachments=tuple(self.attachments))

    def _masses(self, frame) -> np.ndarray:
        n = len(self.rest_x)
        if self.settings.mass_mode == "EVEN":
            return np.full(n, self.settings.mass / n)
        area = topology.vertex_areas(self.rest_x, self.triangles)
        total = area.sum()
        if total <= 0.0:
            self._fail("mass by area needs faces with area (this mesh has none) — use EVEN mass",
                       frame)
        # loose vertices (no face around them) get the mean vertex mass: documented behaviour
        share = np.where(area > 0.0, area / total, 0.0)
        loose = area == 0.0
        mean = self.settings.mass / n
        return np.where(loose, mean, share * (self.settings.mass - mean * loose.sum()))
