"""What the contact solver moves and what moves on its own: the rigid bodies (dynamic ones from
the State, kinematic ones from their animation) and the frame's colliders as bodies that
impulses do not move, posed at any point s of the frame interval."""
from __future__ import annotations

import numpy as np

from ..contact import ColliderFrame
from ..errors import PhysanimError
from ..transforms import TransformPath
from . import quaternion as quat
from .collide import HALF_SPACE, Bodies
from .model import BOX, MESH, RigidBodyModel, RigidBodyState

FLAT = 1e-3  # [m] half thickness given to a two-sided Plane collider


class Posed:
    """Bodies that follow a path over the frame (kinematic rigid bodies, colliders): their
    centres of mass and orientations at any s in [0, 1]."""

    def __init__(self, paths: list[TransformPath], com: np.ndarray):
        self.paths, self.com = paths, com
        # all still (a ground, a wall): one pose for the whole frame, no velocity
        self._still = self._at(0.0) if all(p.static for p in paths) else None

    def __len__(self) -> int:
        return len(self.paths)

    def pose(self, s: float) -> tuple[np.ndarray, np.ndarray]:
        """(x (p, 3), q (p, 4)) at s."""
        if self._still is not None:  # (copies: callers may write into them)
            return self._still[0].copy(), self._still[1].copy()
        return self._at(s)

    def _at(self, s: float) -> tuple[np.ndarray, np.ndarray]:
        if not self.paths:
            return np.zeros((0, 3)), np.zeros((0, 4))
        m = np.stack([p.matrices(s) for p in self.paths])
        lin = m[:, :3, :3]
        rot = lin / np.linalg.norm(lin, axis=1)[:, None, :]
        q = quat.from_matrix(rot)
        return m[:, :3, 3] + np.einsum("nij,nj->ni", rot, self.com), q

    def velocity(self, s0: float, s1: float, h: float) -> tuple[np.ndarray, np.ndarray]:
        """Mean (v, w) over s0..s1, h [s] long: what takes the bodies from one pose to the next."""
        if self._still is not None:
            return np.zeros((len(self), 3)), np.zeros((len(self), 3))
        x0, q0 = self.pose(s0)
        x1, q1 = self.pose(s1)
        turn = quat.normalized(quat.multiply(q1, quat.conjugate(q0)))
        half = np.arccos(np.clip(turn[:, 0], -1.0, 1.0))
        sin = np.sin(half)
        axis = np.where((sin > 1e-12)[:, None], turn[:, 1:] / np.maximum(sin, 1e-300)[:, None], 0.0)
        return (x1 - x0) / h, axis * (2.0 * half / h)[:, None]


def collider_bodies(colliders: list[ColliderFrame], frame: int):
    """The colliders as shapes for the contact solver: (codes, half extents, radii (the
    ground's thickness), paths, friction, restitution, names)."""
    codes, half, radius = [], [], []
    for c in colliders:
        scale = np.linalg.norm(np.asarray(c.matrix0)[:3, :3], axis=0)
        t = c.thickness
        if c.shape == "HALF_SPACE":
            codes.append(HALF_SPACE), half.append((0.0, 0.0, 0.0)), radius.append(t)
        elif c.shape in ("BOX", "PLANE"):
            z = scale[2] + t if c.shape == "BOX" else max(t, FLAT)
            codes.append(BOX), half.append((scale[0] + t, scale[1] + t, z)), radius.append(0.0)
        elif c.shape == "SPHERE":
            if scale.max() > 1.001 * scale.min():
                raise PhysanimError(
                    f"a Sphere collider scaled unevenly {tuple(np.round(scale, 4))} cannot "
                    "stop rigid bodies — scale it evenly, or use a Box collider",
                    obj=c.name, frame=frame, kind="collider")
            codes.append(0), half.append((0.0, 0.0, 0.0)), radius.append(scale.mean() + t)
        else:  # MESH: its local vertices, scaled, are in the collider's own cache entry
            codes.append(MESH), half.append((0.0, 0.0, 0.0)), radius.append(c.thickness)
    paths = [TransformPath(c.matrix0, c.matrix1, c.matrices) for c in colliders]
    return (np.array(codes, np.int64), np.array(half, np.float64).reshape(-1, 3),
            np.array(radius, np.float64), paths,
            np.array([c.friction for c in colliders], np.float64),
            np.array([c.restitution for c in colliders], np.float64),
            tuple(c.name for c in colliders))


def mesh_shapes(model: RigidBodyModel, colliders: list[ColliderFrame], cache) -> dict:
    """Row -> :class:`~.mesh_contacts.MeshShape` of each Mesh body (closed, in its frame at
    the centre of mass) and each Mesh collider (rows after the bodies), a collider's vertices
    scaled by its object's scale (the solver poses it with rotation and translation only)."""
    out = {int(i): cache.shape(model.body_name[i], *model.body_mesh[i], body=True)
           for i in np.nonzero(model.body_shape == MESH)[0]}
    for k, c in enumerate(colliders):
        if c.shape != "MESH":
            continue
        scale = np.linalg.norm(np.asarray(c.matrix0)[:3, :3], axis=0)
        verts = np.asarray(c.vertices0, dtype=np.float64) * scale
        out[model.body_count + k] = cache.shape(c.name, verts, c.triangles, c.thickness)
    return out


def frame_bodies(model: RigidBodyModel, state: RigidBodyState, colliders, posed: Posed,
                 kinematic: np.ndarray, velocities, hulls) -> Bodies:
    """Every body at the frame's start: dynamic ones from ``state``, the posed ones (the bodies
    ``kinematic`` on their paths this frame, then colliders) from their paths; ``velocities``
    is (v, w) of every body."""
    codes, half, radius, _, friction, restitution, names = colliders
    x, q = state.body_x.copy(), state.body_q.copy()
    px, pq = posed.pose(0.0)
    nk = len(kinematic)
    x[kinematic], q[kinematic] = px[:nk], pq[:nk]
    v, w = velocities
    c = len(codes)
    zeros = np.zeros((c, 3))
    return Bodies(
        shape=np.concatenate([model.body_shape.astype(np.int64), codes]),
        half=np.concatenate([model.body_half, half]),
        radius=np.concatenate([model.body_radius, radius]),
        offset=np.concatenate([model.body_shape_offset, zeros]),
        x=np.concatenate([x, px[nk:]]), q=np.concatenate([q, pq[nk:]]),
        v=np.concatenate([v, zeros]), w=np.concatenate([w, zeros]),
        bound=np.concatenate([model.body_bound, np.linalg.norm(half, axis=1) + radius]),
        dynamic=np.concatenate([~np.isin(np.arange(model.body_count), kinematic),
                                np.zeros(c, bool)]),
        friction=np.concatenate([model.body_friction, friction]),
        restitution=np.concatenate([model.body_restitution, restitution]),
        hull_points=model.hull_points, hull_start=np.concatenate([model.body_hull_start,
                                                                  np.zeros(c, np.int64)]),
        hull_count=np.concatenate([model.body_hull_count, np.zeros(c, np.int64)]),
        name=model.body_name + names, hulls=hulls[0],
        hull_index=np.concatenate([hulls[1], np.full(c, -1, np.int64)]))
