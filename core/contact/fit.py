"""The collider shape a triangle mesh *is*: an exact analytic shape when the mesh is one.

A user who tags an object as a collider expects particles to hit what they see. The mesh path
(``MESH``) is exact for any mesh but costs more per particle-step than the analytic shapes, so
a mesh that is exactly a box (Blender's cube, scaled or not) or exactly a filled rectangle
(Blender's plane or grid) collides as ``BOX`` or ``PLANE`` through a fitted local matrix; every
other mesh collides as itself.

Only local geometry is judged: the caller decides whether the mesh can deform during the bake
(modifiers, shape keys), in which case it must stay a ``MESH``.
"""
from __future__ import annotations

import numpy as np

from ..transforms import cross

# relative to the mesh's size: what counts as "flat" and as "on a corner"
FIT_TOLERANCE = 1e-6


def _area(verts: np.ndarray, tris: np.ndarray) -> float:
    a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    return 0.5 * float(np.linalg.norm(cross(b - a, c - a), axis=1).sum())


def fit_analytic_shape(verts: np.ndarray, tris: np.ndarray) -> tuple[str, np.ndarray]:
    """The shape that collides exactly like the triangle mesh, and its local matrix.

    Args:
        verts: (n, 3) local vertex positions [m]. tris: (m, 3) vertex indices.

    Returns:
        ``("BOX", F)`` when the mesh is the surface of an axis-aligned box, ``("PLANE", F)``
        when it is a filled axis-aligned rectangle, else ``("MESH", identity)``. ``F`` (4, 4)
        maps the core shape's local space (|x|, |y|, |z| <= 1; the plane at z = 0) onto the
        mesh's local space, so the collider's world matrix is ``object_world @ F``.
    """
    verts = np.asarray(verts, dtype=np.float64)
    tris = np.asarray(tris, dtype=np.int64).reshape(-1, 3)
    identity = np.eye(4)
    if len(verts) < 3 or len(tris) == 0 or not np.isfinite(verts).all():
        return "MESH", identity
    used = verts[np.unique(tris)]
    lo, hi = used.min(axis=0), used.max(axis=0)
    extent = hi - lo
    size = float(extent.max())
    if size <= 0.0:
        return "MESH", identity
    tol = FIT_TOLERANCE * size
    centre = 0.5 * (lo + hi)
    half = 0.5 * extent
    area = _area(verts, tris)
    flat = extent <= tol
    if flat.sum() == 1:  # a flat mesh: a filled rectangle?
        normal = int(np.argmax(flat))
        u, v = [k for k in range(3) if k != normal]
        if abs(area - extent[u] * extent[v]) <= FIT_TOLERANCE * extent[u] * extent[v] * 10:
            fit = np.zeros((4, 4))
            # core x -> mesh axis u, core y -> axis v, core z -> the normal (a rotation: the
            # three axes keep their cyclic order, so the determinant stays positive)
            fit[u, 0], fit[v, 1] = half[u], half[v]
            fit[normal, 2] = 1.0 if (u, v, normal) in ((0, 1, 2), (1, 2, 0), (2, 0, 1)) else -1.0
            fit[:3, 3] = centre
            fit[3, 3] = 1.0
            return "PLANE", fit
        return "MESH", identity
    if flat.any():
        return "MESH", identity
    # a box (loop cuts allowed): every face lies on a side of the bounding box and the faces
    # cover its surface exactly once (an open box or an extra inner face changes the area)
    box_area = 2.0 * (extent[0] * extent[1] + extent[1] * extent[2] + extent[2] * extent[0])
    tri_pts = verts[tris]  # (m, 3 corners, 3 axes)
    on_side = (((np.abs(tri_pts - lo) <= tol).all(axis=1))
               | ((np.abs(tri_pts - hi) <= tol).all(axis=1))).any(axis=1)
    if on_side.all() and abs(area - box_area) <= FIT_TOLERANCE * box_area * 10:
        fit = np.diag([half[0], half[1], half[2], 1.0])
        fit[:3, 3] = centre
        return "BOX", fit
    return "MESH", identity
