"""Closest points on a mesh and signed distances, batched over query points.

For particle contact: how far each particle is from the surface, where the nearest surface point
is, and on which side of the surface the particle lies.

Traversal: (point, node) pairs level by level. A pair survives while the volume's distance lower
bound does not exceed the point's best upper bound, which every visited node tightens (the
distance to one of its vertices bounds the distance to the mesh). Leaves compute exact closest
points on their triangles (the face when the point projects inside it, else the nearest point
on one of its three edges, which also serves zero-area triangles).

Sign (pseudo-normals, :attr:`.mesh.TriangleMesh.pseudo_normals`): a point is inside (negative)
when it lies behind the angle-weighted pseudo-normal of the feature — face, edge or corner —
its closest point lies on. For a closed, consistently wound mesh this is exactly inside/outside
(Baerentzen & Aanaes 2005). For open or non-manifold meshes it is the side of the locally
nearest surface, as its winding faces: the back of a single-sided plane is "inside". Where only
zero-area triangles meet the pseudo-normal vanishes and the sign is positive: zero-area geometry
has no inside.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import cross, take, transform_points, transform_vectors
from .bounding import PAD_REL, similarity_scale, world_frame
from .bvh import BVH
from .cells import TriangleCells
from .cost import QueryCost
from .mesh import check_points

CHUNK = 1 << 18
FACE, EDGE, CORNER = 0, 1, 4  # feature codes: FACE, EDGE + k (edge k -> k+1), CORNER + k


@dataclass(frozen=True)
class ClosestPoints:
    """Nearest surface points of n query points.

    Attributes:
        distance: (n,) [m] unsigned; inf where nothing lies within ``max_distance``.
        signed_distance: (n,) [m] negative inside (see the module docstring).
        point: (n, 3) closest surface points [m].
        normal: (n, 3) unit pseudo-normal of the closest feature, pointing to the outside: the
            sign of ``signed_distance`` is the sign of (query point - point) . normal.
        triangle: (n,) int64 triangle of the closest point, -1 where none.
        feature: (n,) int8 0 face, 1..3 edge k (corner k -> k + 1), 4..6 corner k, -1 none.
        n_v, n_p, n_u: the seed's cost terms.
    """

    distance: np.ndarray
    signed_distance: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    triangle: np.ndarray
    feature: np.ndarray
    n_v: int
    n_p: int
    n_u: int

    @property
    def cost(self) -> QueryCost:
        return QueryCost(self.n_v, self.n_p, self.n_u)


def closest_points(bvh: BVH, points, *, max_distance: float = np.inf,
                   matrix=None, cells: TriangleCells | None = None) -> ClosestPoints:
    """Closest surface point and signed distance of each query point.

    Args:
        bvh: the mesh's hierarchy.
        points: (n, 3) query points [m] (world space when ``matrix`` is given).
        max_distance: ignore surface farther than this [m] (faster for contact queries).
        matrix: (4, 4) the mesh's local-to-world transform (rotation, translation, uniform
            scale); results are then in world space.
        cells: the grid over ``bvh`` (:mod:`.cells`), for the points whose ball of radius
            ``max_distance`` spans a few of its cells; the answers are the same as without it.
    """
    p = check_points(bvh.mesh.name, "query point", points, kind="mesh")
    if not np.all(np.asarray(max_distance) > 0):
        raise ValueError(f"max_distance must be > 0 (got {np.min(max_distance)})")
    scale = 1.0
    if matrix is not None:
        scale = similarity_scale(matrix, bvh.mesh.name)
        matrix, inv = world_frame(matrix, bvh.mesh.name)
        p = transform_points(inv, p)
    dist, tri_id, q, feature, n_v, n_p = _search(bvh, p, max_distance / scale, cells)
    found = tri_id >= 0
    normal = np.zeros((len(p), 3))
    normal[found] = take(bvh.mesh.feature_normals, 7 * tri_id[found] + feature[found])
    side = np.einsum("ij,ij->i", p - q, normal)
    sign = np.where(side < 0.0, -1.0, 1.0)
    if matrix is not None:
        q = transform_points(matrix, q)
        normal = transform_vectors(matrix[:3, :3], normal) / scale  # rotation (or mirror) part
        dist = dist * scale
    return ClosestPoints(dist, np.where(found, sign * dist, np.inf), q, normal, tri_id,
                         feature, n_v, n_p, 0)


def closest_on_triangles(p: np.ndarray, tri: np.ndarray):
    """Closest points of (m, 3) points on (m, 3, 3) closed triangles (zero-area ones too).

    Returns:
        (point (m, 3), squared distance (m,), feature code (m,) int8).
    """
    best_d2 = np.full(len(p), np.inf)
    best_q = np.zeros_like(p)
    feature = np.zeros(len(p), dtype=np.int8)
    for k in range(3):
        v, e = tri[:, k], tri[:, (k + 1) % 3] - tri[:, k]
        ee = np.einsum("ij,ij->i", e, e)
        s = np.einsum("ij,ij->i", p - v, e) / np.where(ee > 0.0, ee, 1.0)
        s = np.clip(np.where(ee > 0.0, s, 0.0), 0.0, 1.0)
        q = v + s[:, None] * e
        d2 = np.einsum("ij,ij->i", p - q, p - q)
        code = np.where(s <= 0.0, CORNER + k, np.where(s >= 1.0, CORNER + (k + 1) % 3, EDGE + k))
        better = d2 < best_d2
        best_d2 = np.where(better, d2, best_d2)
        best_q = np.where(better[:, None], q, best_q)
        feature = np.where(better, code, feature).astype(np.int8)
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    n = cross(b - a, c - a)
    nn = np.einsum("ij,ij->i", n, n)
    inside = nn > 0.0
    for v, w in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", n, cross(w - v, p - v)) >= 0.0
    h = np.einsum("ij,ij->i", n, p - a) / np.where(inside, nn, 1.0)
    face_q = p - h[:, None] * n
    face_d2 = h * h * nn
    use = inside & (face_d2 <= best_d2)
    best_q = np.where(use[:, None], face_q, best_q)
    best_d2 = np.where(use, face_d2, best_d2)
    feature = np.where(use, FACE, feature).astype(np.int8)
    return best_q, best_d2, feature


def _search(bvh: BVH, p: np.ndarray, max_distance, cells: TriangleCells | None = None):
    """Each point's nearest triangle within ``max_distance`` (one for all, or one each)."""
    n = len(p)
    bound = np.array(np.broadcast_to(np.asarray(max_distance, np.float64), (n,)))
    max_distance = bound.copy()  # each point's own limit
    best_d = np.full(n, np.inf)
    best_tri = np.full(n, -1, dtype=np.int64)
    best_q = np.zeros((n, 3))
    best_f = np.full(n, -1, dtype=np.int8)
    margin = PAD_REL * max(bvh.mesh.scale, float(np.abs(p).max(initial=0.0)), 1e-300)
    tri = bvh.ordered_triangles
    pt = np.arange(n)
    n_v = n_p = 0
    if cells is not None and cells.usable and n and np.isfinite(max_distance).all():
        reach = (max_distance + margin)[:, None]
        q, pos, pt = cells.candidates(p - reach, p + reach)
        n_v += n - len(pt)
        n_p += _pair_tests(bvh, p, q, pos, tri, bound, best_d, best_tri, best_q, best_f,
                           max_distance)
    node = np.zeros(len(pt), dtype=np.int64)
    while len(pt):
        lower = np.concatenate([bvh.kind.distance_bound(take(bvh.node_bv, node[s:s + CHUNK]),
                                                        take(p, pt[s:s + CHUNK]))
                                for s in range(0, len(pt), CHUNK)])
        n_v += len(pt)
        keep = lower <= bound[pt] + margin
        pt, node = pt[keep], node[keep]
        rep = tri[bvh.node_first[node], 0]  # any vertex under a node bounds the distance
        np.minimum.at(bound, pt, np.sqrt(np.einsum("ij,ij->i", p[pt] - rep, p[pt] - rep)))
        leaf = bvh.node_is_leaf[node]
        if leaf.any():
            n_p += _leaf_tests(bvh, p, pt[leaf], node[leaf], tri, bound, best_d, best_tri,
                               best_q, best_f, max_distance)
        kids = bvh.node_child[node[~leaf]]
        real = kids >= 0
        pt = np.repeat(pt[~leaf], real.sum(axis=1))
        node = kids[real]
    return best_d, best_tri, best_q, best_f, n_v, n_p


def _leaf_tests(bvh, p, pt, node, tri, bound, best_d, best_tri, best_q, best_f,
                max_distance) -> int:
    count = bvh.node_tri_count[node]
    rep = np.repeat(np.arange(len(pt)), count)
    pos = bvh.node_first[node][rep] + np.arange(count.sum()) - np.repeat(np.cumsum(count) - count,
                                                                         count)
    return _pair_tests(bvh, p, pt[rep], pos, tri, bound, best_d, best_tri, best_q, best_f,
                       max_distance)


def _pair_tests(bvh, p, s, pos, tri, bound, best_d, best_tri, best_q, best_f,
                max_distance) -> int:
    """Points s (k,) against the triangles at leaf-order positions pos (k,): improves the
    best arrays in place; returns k."""
    for c in range(0, len(s), CHUNK):
        sc, pc = s[c:c + CHUNK], pos[c:c + CHUNK]
        q, d2, f = closest_on_triangles(take(p, sc), take(tri, pc))
        d = np.sqrt(d2)
        tri_id = bvh.tri_order[pc]
        o = np.lexsort((tri_id, d, sc))  # nearest per point, ties to the lowest triangle id
        sc, d, tri_id, q, f = sc[o], d[o], tri_id[o], q[o], f[o]
        head = np.ones(len(sc), dtype=bool)
        head[1:] = sc[1:] != sc[:-1]
        sc, d, tri_id, q, f = sc[head], d[head], tri_id[head], q[head], f[head]
        better = ((d < best_d[sc]) | ((d == best_d[sc]) & (tri_id < best_tri[sc])))
        better &= d <= max_distance[sc]
        g = sc[better]
        best_d[g], best_tri[g] = d[better], tri_id[better]
        best_q[g], best_f[g] = q[better], f[better]
        bound[g] = np.minimum(bound[g], d[better])
    return len(s)
