"""Rigid bodies as colliders for the other systems: particles and spring meshes meet a frame's
rigid bodies as shapes moving from their pose at the frame's start to their pose at its end.

Boxes and spheres become the analytic Box and Sphere colliders (scaled unit shapes); convex
hulls and capsules become Mesh colliders over their hull's triangles, Mesh bodies Mesh colliders
over their own.
"""
from __future__ import annotations

import numpy as np

from ..collision.hull import convex_hull
from ..contact import ColliderFrame
from . import quaternion as quat
from .model import BOX, CAPSULE, HULL, MESH, SPHERE, RigidBodyModel

CAPSULE_SEGMENTS = 12  # around a capsule's axis, for its collider mesh


def _capsule_points(radius: float, half: float, offset: np.ndarray) -> np.ndarray:
    """Points whose hull is a capsule (two tessellated hemispheres along z), from the centre of
    mass."""
    angle = np.linspace(0.0, 2.0 * np.pi, CAPSULE_SEGMENTS, endpoint=False)
    rings = []
    for lat in np.linspace(0.0, 0.5 * np.pi, 4):
        r, z = radius * np.cos(lat), radius * np.sin(lat)
        ring = np.stack([r * np.cos(angle), r * np.sin(angle), np.zeros_like(angle)], 1)
        rings += [ring + (0.0, 0.0, half + z), ring - (0.0, 0.0, half + z)]
    return np.concatenate(rings) + offset


def shapes(model: RigidBodyModel) -> dict:
    """Per HULL, CAPSULE or MESH body, (local vertices (from the centre of mass), triangles) of
    the mesh it collides as (made once: they do not change)."""
    out = {int(i): model.body_mesh[i] for i in np.nonzero(model.body_shape == MESH)[0]}
    for i in np.nonzero(np.isin(model.body_shape, (HULL, CAPSULE)))[0]:
        if model.body_shape[i] == HULL:
            s, c = model.body_hull_start[i], model.body_hull_count[i]
            points = model.hull_points[s:s + c]
        else:
            points = _capsule_points(model.body_radius[i], model.body_half[i, 2],
                                     model.body_shape_offset[i])
        hull = convex_hull(points)
        out[int(i)] = (hull.points, hull.triangles)
    return out


def _matrix(x, q, offset, scale) -> np.ndarray:
    m = np.eye(4)
    r = quat.to_matrix(q[None])[0]
    m[:3, :3] = r * scale
    m[:3, 3] = x + r @ offset
    return m


def frames(model: RigidBodyModel, meshes: dict, start, end) -> list[ColliderFrame]:
    """The dynamic bodies as colliders moving from ``start`` to ``end`` ((x, q) each)."""
    (x0, q0), (x1, q1) = start, end
    out = []
    for i in np.nonzero(~model.body_kinematic)[0]:
        code, name = int(model.body_shape[i]), model.body_name[i]
        args = (float(model.body_restitution[i]), float(model.body_friction[i]))
        if code in (BOX, SPHERE):
            scale = model.body_half[i] if code == BOX else np.full(3, model.body_radius[i])
            offset = model.body_shape_offset[i]
            out.append(ColliderFrame(name, "BOX" if code == BOX else "SPHERE",
                                     _matrix(x0[i], q0[i], offset, scale),
                                     _matrix(x1[i], q1[i], offset, scale), *args))
        else:
            verts, tris = meshes[int(i)]
            zero = np.zeros(3)
            out.append(ColliderFrame(name, "MESH", _matrix(x0[i], q0[i], zero, np.ones(3)),
                                     _matrix(x1[i], q1[i], zero, np.ones(3)), *args,
                                     vertices0=verts, vertices1=verts, triangles=tris))
    return out
