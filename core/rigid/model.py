"""Rigid bodies: per-body settings -> builder -> frozen Model (structure of arrays) -> State.

A body is simulated at its centre of mass: the State holds x (centre of mass, world), q (unit
quaternion [w, x, y, z] of the body's axes: the object's rotation), P (linear momentum) and L
(angular momentum), as Witkin & Baraff teach; v = P / M, I(t) = R I_body R^T, w = I(t)^-1 L.
Keeping L (not w) makes torque-free motion conserve angular momentum exactly.

Shapes live in the body's local frame (the object's axes, its scale already applied), centred
on the shape's own centre ``body_shape_offset`` away from the centre of mass.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..collision.hull import convex_hull
from .joints import JointModel, JointSettings, JointState, joint_model
from ..errors import PhysanimError
from ..transforms import slerp
from ..validate import frozen
from . import quaternion as quat
from .mass import MassProperties
from .warm import Kept

SHAPES = ("SPHERE", "BOX", "CAPSULE", "HULL", "MESH")
SPHERE, BOX, CAPSULE, HULL, MESH = range(5)
MAX_SPEED = 1.0e5  # [m/s], [rad/s]: initial velocities beyond this are input errors


@dataclass(frozen=True)
class RigidBodySettings:
    """One body, in world units (the object's scale applied to its shape).

    Attributes:
        name: the object's name (messages).
        shape: one of :data:`SHAPES`.
        mass_properties: mass [kg], centre of mass (local, from the object's origin) and the
            inertia tensor about it (local axes).
        half_extents: (3,) BOX half sizes [m]; CAPSULE: half_extents[2] is the half length of
            its axis (local Z) between the cap centres.
        radius: SPHERE and CAPSULE radius [m].
        hull: (m, 3) HULL vertices, local (from the object's origin) [m].
        mesh: MESH: (vertices (m, 3) local from the object's origin [m], triangles (t, 3)) of
            a closed mesh; the body collides as this concave surface (its convex hull is
            made from the vertices for flat colliders).
        shape_centre: (3,) where the shape's centre lies, local from the object's origin.
        restitution, friction: contact coefficients (combined with the other side's).
        linear_damping, angular_damping: fraction of velocity lost per second [1/s].
        kinematic: follows its animation; pushes others, is not pushed.
        position, orientation: the object's origin [m] and rotation (unit quaternion) at start.
        velocity, angular_velocity: of the centre of mass at start [m/s], [rad/s] (world).
    """

    name: str
    shape: str
    mass_properties: MassProperties
    half_extents: tuple = (0.0, 0.0, 0.0)
    radius: float = 0.0
    hull: np.ndarray | None = None
    mesh: tuple | None = None
    shape_centre: tuple = (0.0, 0.0, 0.0)
    restitution: float = 0.0
    friction: float = 0.5
    linear_damping: float = 0.04
    angular_damping: float = 0.1
    kinematic: bool = False
    position: tuple = (0.0, 0.0, 0.0)
    orientation: tuple = (1.0, 0.0, 0.0, 0.0)
    velocity: tuple = (0.0, 0.0, 0.0)
    angular_velocity: tuple = (0.0, 0.0, 0.0)

    def __post_init__(self):
        def fail(message: str):
            raise PhysanimError(message, obj=self.name, kind="rigid body")

        if self.shape not in SHAPES:
            fail(f"unknown shape {self.shape!r}; choose one of {', '.join(SHAPES)}")
        for key in ("restitution", "friction", "linear_damping", "angular_damping", "radius"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value >= 0.0):
                fail(f"{key} must be finite and >= 0 (got {value})")
        if self.restitution > 1.0:
            fail(f"restitution must be at most 1 (got {self.restitution})")
        for key in ("half_extents", "shape_centre", "position", "velocity", "angular_velocity"):
            value = np.asarray(getattr(self, key), dtype=np.float64)
            if value.shape != (3,) or not np.isfinite(value).all():
                fail(f"{key} must be 3 finite numbers (got {getattr(self, key)})")
        for key in ("velocity", "angular_velocity"):
            if np.abs(getattr(self, key)).max() > MAX_SPEED:
                fail(f"{key} {tuple(getattr(self, key))} is beyond {MAX_SPEED:g}")
        q = np.asarray(self.orientation, dtype=np.float64)
        if q.shape != (4,) or not np.isfinite(q).all() or abs(np.linalg.norm(q) - 1.0) > 1e-6:
            fail(f"orientation must be a unit quaternion (got {self.orientation})")
        if self.shape == "BOX" and min(self.half_extents) <= 0.0:
            fail(f"a box needs positive sizes (got half extents {tuple(self.half_extents)})")
        if self.shape in ("SPHERE", "CAPSULE") and self.radius <= 0.0:
            fail(f"a {self.shape.lower()} needs a positive radius (got {self.radius})")
        if self.shape == "HULL" and (self.hull is None or len(self.hull) < 4):
            fail("a convex hull needs at least 4 vertices that enclose a volume")
        if self.shape == "MESH":
            if self.mesh is None or len(self.mesh) != 2:
                fail("a Mesh body needs its vertices and triangles")
            verts, tris = (np.asarray(a) for a in self.mesh)
            if verts.ndim != 2 or verts.shape[1] != 3 or len(verts) < 4 or \
                    not np.isfinite(verts).all():
                fail("a Mesh body needs at least 4 finite vertices")
            if tris.ndim != 2 or tris.shape[1] != 3 or not len(tris) or tris.min() < 0 or \
                    tris.max() >= len(verts):
                fail("a Mesh body needs triangles indexing its vertices")


@dataclass(frozen=True)
class RigidBodyModel:
    """Read-only arrays of every body (n of them); hull vertices concatenated.

    Attributes:
        body_name: names. body_shape: (n,) int8 codes of :data:`SHAPES`.
        body_half: (n, 3) box half extents / capsule half length in [2] [m].
        body_radius: (n,) [m]. body_shape_offset: (n, 3) shape centre from the centre of mass,
            local [m]. body_com: (n, 3) centre of mass from the object's origin, local [m].
        body_bound: (n,) radius of a sphere about the centre of mass holding the shape [m].
        body_mass, body_inv_mass: (n,) [kg], [1/kg] (a body on its path this frame takes no
            impulse whatever its mass: the solver's per-frame masses say so).
        body_inertia, body_inv_inertia: (n, 3, 3) about the centre of mass, local axes.
        body_restitution, body_friction, body_linear_damping, body_angular_damping: (n,).
        body_kinematic: (n,) bool: follows its animation at the start (the frame inputs say
            which bodies follow their paths in each frame).
        hull_points: (m, 3) hull vertices from the centre of mass, local [m];
        body_hull_start, body_hull_count: (n,) each body's range in it (0 for other shapes;
            a MESH body's convex hull vertices: what can touch a flat collider).
        body_mesh: per body, None or a MESH body's (vertices from the centre of mass, local
            [m], triangles) (read-only arrays).
        joints: the joints between the bodies (:mod:`physanim.core.constraints.joints`).
    """

    body_name: tuple[str, ...]
    body_shape: np.ndarray
    body_half: np.ndarray
    body_radius: np.ndarray
    body_shape_offset: np.ndarray
    body_com: np.ndarray
    body_bound: np.ndarray
    body_mass: np.ndarray
    body_inv_mass: np.ndarray
    body_inertia: np.ndarray
    body_inv_inertia: np.ndarray
    body_restitution: np.ndarray
    body_friction: np.ndarray
    body_linear_damping: np.ndarray
    body_angular_damping: np.ndarray
    body_kinematic: np.ndarray
    hull_points: np.ndarray
    body_hull_start: np.ndarray
    body_hull_count: np.ndarray
    body_mesh: tuple = ()
    initial: tuple = field(repr=False, default=())  # (x, q, P, L) at the start
    joints: JointModel = field(default_factory=JointModel)

    @property
    def body_count(self) -> int:
        return len(self.body_name)

    def state(self) -> RigidBodyState:
        x, q, p, l_ = (a.copy() for a in self.initial)
        return RigidBodyState(x, q, p, l_, joints=self.joints.state())


@dataclass
class RigidBodyState:
    """Time-varying, (n, ...) each: body_x centre of mass [m], body_q unit quaternion,
    body_P linear momentum [kg m/s], body_L angular momentum about the centre of mass
    [kg m^2/s], all world. ``contacts``: the last frame's contacts, kept for the bodies
    that have not moved and warm-starting the others (:mod:`.warm`); the sleep bookkeeping
    (:mod:`.sleep`)."""

    body_x: np.ndarray
    body_q: np.ndarray
    body_P: np.ndarray
    body_L: np.ndarray
    contacts: Kept = field(default_factory=Kept.none)
    body_asleep: np.ndarray | None = None  # (n,) bool: resting, not simulated (:mod:`.sleep`)
    body_slow: np.ndarray | None = None  # (n,) int: consecutive slow frames
    body_island: np.ndarray | None = None  # (n,) int: the island a sleeping body sleeps in
    joints: JointState | None = None  # the joints' impulses and breaks

    def __post_init__(self):
        n = len(self.body_x)
        if self.body_asleep is None:
            self.body_asleep = np.zeros(n, bool)
        if self.body_slow is None:
            self.body_slow = np.zeros(n, np.int64)
        if self.body_island is None:
            self.body_island = np.full(n, -1, np.int64)

    def pose(self) -> RigidBodyState:
        """A copy of the bodies' poses and momenta now, for drawing (see :meth:`between`)."""
        return RigidBodyState(self.body_x.copy(), self.body_q.copy(), self.body_P.copy(),
                              self.body_L.copy())

    @staticmethod
    def between(a: RigidBodyState, b: RigidBodyState, w: float) -> RigidBodyState:
        """The bodies at the fraction ``w`` of one sub-step from pose ``a`` to pose ``b``:
        centres and momenta on straight lines, orientations by slerp (a sub-step turns a body
        at one angular velocity)."""
        if w >= 1.0:
            return b
        return RigidBodyState(a.body_x + w * (b.body_x - a.body_x),
                              slerp(a.body_q, b.body_q, w),
                              a.body_P + w * (b.body_P - a.body_P),
                              a.body_L + w * (b.body_L - a.body_L))

    def origins(self, model: RigidBodyModel) -> np.ndarray:
        """(n, 3) world positions of the objects' origins (x - R com)."""
        return self.body_x - quat.rotate(self.body_q, model.body_com)


class RigidBodyBuilder:
    """Collects bodies and the joints between them (:meth:`add_body`, :meth:`add_joint`
    return their index); :meth:`finalize` freezes them."""

    def __init__(self):
        self._bodies: list[RigidBodySettings] = []
        self._joints: list[JointSettings] = []

    def add_body(self, settings: RigidBodySettings) -> int:
        self._bodies.append(settings)
        return len(self._bodies) - 1

    def add_joint(self, settings: JointSettings) -> int:
        """A joint between bodies already added (or a body and a frame)."""
        self._joints.append(settings)
        return len(self._joints) - 1

    def finalize(self) -> RigidBodyModel:
        b = self._bodies
        n = len(b)
        com = np.array([s.mass_properties.com for s in b], dtype=np.float64).reshape(n, 3)
        offset = np.array([s.shape_centre for s in b], dtype=np.float64).reshape(n, 3) - com
        meshes = tuple(_mesh(s, c) for s, c in zip(b, com))
        hulls = [np.asarray(s.hull, dtype=np.float64).reshape(-1, 3) - c if s.shape == "HULL"
                 else _hull_of(m[0]) if m is not None else np.zeros((0, 3))
                 for s, c, m in zip(b, com, meshes)]
        counts = np.array([len(h) for h in hulls], dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64) if n else counts
        half = np.array([s.half_extents for s in b], dtype=np.float64).reshape(n, 3)
        radius = np.array([s.radius for s in b], dtype=np.float64)
        kinematic = np.array([s.kinematic for s in b], dtype=bool)
        mass = np.array([s.mass_properties.mass for s in b], dtype=np.float64)
        inertia = np.array([s.mass_properties.inertia for s in b], dtype=np.float64).reshape(n, 3, 3)
        inv_inertia = np.linalg.inv(inertia) if n else inertia.copy()
        bound = np.array([_bound(s, o, h) for s, o, h in zip(b, offset, hulls)])
        initial = self._initial(com, mass, inertia)
        joints = joint_model(self._joints, initial[0], quat.to_matrix(initial[1]))
        return RigidBodyModel(
            tuple(s.name for s in b), frozen([SHAPES.index(s.shape) for s in b], np.int8),
            frozen(half), frozen(radius), frozen(offset), frozen(com), frozen(bound),
            frozen(mass), frozen(1.0 / mass), frozen(inertia),
            frozen(inv_inertia),
            *(frozen([getattr(s, k) for s in b]) for k in (
                "restitution", "friction", "linear_damping", "angular_damping")),
            frozen(kinematic, bool), frozen(np.concatenate(hulls) if n else np.zeros((0, 3))),
            frozen(starts, np.int64), frozen(counts, np.int64), meshes, initial, joints)

    def _initial(self, com, mass, inertia) -> tuple:
        b = self._bodies
        n = len(b)
        q = quat.normalized(np.array([s.orientation for s in b], dtype=np.float64).reshape(n, 4))
        x = np.array([s.position for s in b], dtype=np.float64).reshape(n, 3) + quat.rotate(q, com)
        v = np.array([s.velocity for s in b], dtype=np.float64).reshape(n, 3)
        w = np.array([s.angular_velocity for s in b], dtype=np.float64).reshape(n, 3)
        r = quat.to_matrix(q)
        world_inertia = r @ inertia @ np.swapaxes(r, 1, 2)
        return x, q, mass[:, None] * v, np.einsum("nij,nj->ni", world_inertia, w)


def _mesh(s: RigidBodySettings, com: np.ndarray):
    """A MESH body's (vertices from the centre of mass, triangles), read-only; else None."""
    if s.shape != "MESH":
        return None
    verts, tris = s.mesh
    return (frozen(np.asarray(verts, dtype=np.float64) - com),
            frozen(np.asarray(tris, dtype=np.int64), np.int64))


def _hull_of(points: np.ndarray) -> np.ndarray:
    """The vertices of the convex hull of ``points`` (m, 3) (all of them when flat)."""
    hull = convex_hull(points)
    return hull.points[hull.vertices] if hull.dimension == 3 else np.asarray(points)


def _bound(s: RigidBodySettings, offset: np.ndarray, hull: np.ndarray) -> float:
    """Radius about the centre of mass of a sphere holding the body's shape."""
    centre = float(np.linalg.norm(offset))
    if s.shape == "SPHERE":
        return centre + s.radius
    if s.shape == "BOX":
        return centre + float(np.linalg.norm(s.half_extents))
    if s.shape == "CAPSULE":
        return centre + s.radius + abs(s.half_extents[2])
    return float(np.linalg.norm(hull, axis=1).max())
