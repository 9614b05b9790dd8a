"""Spring families of a mesh: structural (edges), shear (face diagonals), bending hinges
(triangle pairs sharing an edge) and distance-2 bending springs.

All functions take plain arrays — vertex positions, edges, polygons as (loop_start, loop_total,
loop_vertices), triangles — so any mesh source (Blender, a file, a test) can feed them.
"""
from __future__ import annotations

import numpy as np

from ..transforms import cross


def unique_pairs(pairs: np.ndarray) -> np.ndarray:
    """Sorted, de-duplicated vertex pairs (m, 2) with a < b; pairs with a == b are dropped."""
    pairs = np.sort(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), axis=1)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    return np.unique(pairs, axis=0) if len(pairs) else pairs


def polygon_diagonals(loop_start: np.ndarray, loop_total: np.ndarray,
                      loop_vertices: np.ndarray) -> np.ndarray:
    """Shear springs: every pair of non-adjacent corners of each polygon with >= 4 corners.

    Args:
        loop_start, loop_total: (p,) first loop and corner count of each polygon.
        loop_vertices: (l,) vertex of each loop (corner).
    """
    out = []
    total = np.asarray(loop_total)
    for k in np.unique(total[total >= 4]):  # loop over polygon sizes, vectorised per size
        starts = np.asarray(loop_start)[total == k]
        corners = np.asarray(loop_vertices)[starts[:, None] + np.arange(k)]  # (p_k, k)
        a, b = np.triu_indices(k, 2)
        keep = ~((a == 0) & (b == k - 1))  # first and last corners are adjacent
        out.append(np.stack([corners[:, a[keep]], corners[:, b[keep]]], axis=-1).reshape(-1, 2))
    return unique_pairs(np.concatenate(out)) if out else np.zeros((0, 2), np.int64)


def hinges(triangles: np.ndarray) -> np.ndarray:
    """Bending hinges: (h, 4) vertex indices (e0, e1, w0, w1) for each interior edge shared by
    exactly two triangles: the shared edge e0-e1 and the two wing vertices opposite it.

    Triangles are oriented consistently for a manifold: the first triangle is (e0, e1, w0) and
    the second (e1, e0, w1). Edges with one or more than two triangles are not hinges.
    """
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if len(tris) == 0:
        return np.zeros((0, 4), np.int64)
    # each triangle contributes three directed edges (a, b) with opposite vertex c
    a = tris[:, [0, 1, 2]].ravel()
    b = tris[:, [1, 2, 0]].ravel()
    c = tris[:, [2, 0, 1]].ravel()
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    order = np.lexsort((hi, lo))
    lo, hi, a, b, c = lo[order], hi[order], a[order], b[order], c[order]
    key_change = np.ones(len(lo), dtype=bool)
    key_change[1:] = (lo[1:] != lo[:-1]) | (hi[1:] != hi[:-1])
    group = np.cumsum(key_change) - 1
    counts = np.bincount(group)
    first = np.nonzero(key_change)[0]
    two = counts[group[first]] == 2
    i = first[two]
    j = i + 1
    return np.stack([a[i], b[i], c[i], c[j]], axis=1)


def distance2_pairs(hinge: np.ndarray) -> np.ndarray:
    """Distance-2 bending springs: the two wing vertices of every hinge."""
    return unique_pairs(hinge[:, 2:4]) if len(hinge) else np.zeros((0, 2), np.int64)


def hinge_geometry(x: np.ndarray, hinge: np.ndarray):
    """Per hinge: corners x0..x3 (e0, e1, w0, w1), edge e = x1 - x0, its length, the face
    normals n1 = e x (x2 - x0), n2 = (x3 - x0) x e (unnormalised) and the signed dihedral angle
    (0 for a flat pair of triangles). Hinge indices must be valid for x (the model builder
    checks them): the gathers clip rather than check, for speed."""
    corners = [np.take(x, hinge[:, k], axis=0, mode="clip") for k in range(4)]
    x0 = corners[0]
    e = corners[1] - x0
    length = np.sqrt(np.einsum("ij,ij->i", e, e))
    n1 = cross(e, corners[2] - x0)
    n2 = cross(corners[3] - x0, e)
    sin = np.einsum("ij,ij->i", cross(n1, n2), e) / np.where(length > 0, length, 1.0)
    theta = np.arctan2(sin, np.einsum("ij,ij->i", n1, n2))
    return corners, e, length, n1, n2, theta


def dihedral_angles(x: np.ndarray, hinge: np.ndarray) -> np.ndarray:
    """Signed dihedral angle (h,) [rad] of each hinge: 0 for a flat pair of triangles."""
    return hinge_geometry(x, np.asarray(hinge))[5]


def vertex_areas(x: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """A third of the area of every triangle around each vertex (n,) [m^2]."""
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    area = np.zeros(len(x))
    if len(tris):
        doubled = cross(x[tris[:, 1]] - x[tris[:, 0]], x[tris[:, 2]] - x[tris[:, 0]])
        third = np.linalg.norm(doubled, axis=1) / 6.0
        for k in range(3):
            area += np.bincount(tris[:, k], weights=third, minlength=len(x))
    return area


def signed_volume(x: np.ndarray, triangles: np.ndarray) -> float:
    """Signed volume [m^3] enclosed by a closed, consistently oriented triangle mesh (positive
    when the normals point outwards; negative when it turned inside out)."""
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    a, b, c = x[tris[:, 0]], x[tris[:, 1]], x[tris[:, 2]]
    return float(np.einsum("ij,ij->i", a, cross(b, c)).sum() / 6.0)
