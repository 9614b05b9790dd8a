"""First hit of segments and rays on a mesh, batched: time of impact, point, normal.

This is the continuous collision query for particles: the segment from a particle's old to its
new position (in the mesh's local frame at the particle's own times) either crosses the surface
or not, and if it does, the first crossing is where to bounce.

Segment-triangle test: exact orientation signs (:mod:`.predicates`) decide whether the closed
segment meets the closed triangle, so the test is watertight: a segment through a shared edge or
vertex of a mesh hits at least one of the triangles there, never slipping between them. Only the
time of impact itself, t = d0 / (d0 - d1) from the endpoints' signed volumes, is rounded.
Conventions:

* a segment starting on the surface hits at t = 0 (a particle resting on it);
* a segment lying in a triangle's plane does not hit that triangle (it grazes, never crosses);
  hence a segment of zero length (a point at rest) hits nothing and is not tested;
* zero-area triangles have no surface and are never hit;
* the reported normal is the triangle's unit normal turned to face the segment's start, with
  ``front`` telling whether that is the winding's side: thin single-sided meshes bounce from
  either side.

Traversal: (segment, node) pairs level by level; a pair survives while its volume's parameter
interval overlaps [0, best t so far of that segment].
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import cross, norm_rows, take, transform_points, transform_vectors
from .bounding import PAD_REL, world_frame
from .bvh import BVH
from .cells import TriangleCells
from .cost import QueryCost
from .mesh import check_points
from .predicates import orient3d, orient3d_value

CHUNK = 1 << 18  # (segment, node) or (segment, triangle) pairs per batch
SHORT = 0.01  # segments shorter than this times the mesh's diameter are culled by their box


@dataclass(frozen=True)
class SegmentHits:
    """First hits of n segments (or rays).

    Attributes:
        hit: (n,) bool.
        t: (n,) time of impact: the fraction of the segment (rays: in units of the direction)
            travelled before the hit; inf where nothing is hit.
        point: (n, 3) hit points [m] (zeros where nothing is hit).
        normal: (n, 3) unit normals at the hit facing the segment's start (zeros elsewhere).
        front: (n,) bool, the segment hit the side the triangle's winding normal points to.
        triangle: (n,) int64 triangle ids, -1 where nothing is hit.
        n_v, n_p, n_u: the seed's cost terms.
    """

    hit: np.ndarray
    t: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    front: np.ndarray
    triangle: np.ndarray
    n_v: int
    n_p: int
    n_u: int

    @property
    def cost(self) -> QueryCost:
        return QueryCost(self.n_v, self.n_p, self.n_u)


def segment_hits(bvh: BVH, start, end, matrix=None, cells: TriangleCells | None = None
                 ) -> SegmentHits:
    """First triangle each segment start -> end meets.

    Args:
        bvh: the mesh's hierarchy.
        start, end: (n, 3) segment end points [m], in world space when ``matrix`` is given,
            else in the mesh's local frame.
        matrix: (4, 4) the mesh's local-to-world transform (any invertible affine map); results
            are then in world space too.
        cells: the grid over ``bvh`` (:mod:`.cells`), for the segments whose box spans a few
            of its cells; the answers are the same as without it.
    """
    p0 = check_points(bvh.mesh.name, "segment start", start, kind="mesh")
    p1 = check_points(bvh.mesh.name, "segment end", end, kind="mesh")
    if p0.shape != p1.shape:
        raise ValueError(f"segment starts and ends differ in shape ({p0.shape} vs {p1.shape})")
    if matrix is not None:
        matrix, inv = world_frame(matrix, bvh.mesh.name)
        p0, p1 = transform_points(inv, p0), transform_points(inv, p1)
    t, tri_id, n_v, n_p = _first_hits(bvh, p0, p1, cells)
    return _report(bvh, p0, p1, t, tri_id, n_v, n_p, matrix, 1.0)


def ray_hits(bvh: BVH, origin, direction, max_t: float = np.inf, matrix=None) -> SegmentHits:
    """First triangle each ray origin + t * direction, 0 <= t <= max_t, meets.

    The ray is cut to a segment ending beyond the mesh's bounds; ``t`` is reported in units of
    ``direction`` (a distance when it is a unit vector).
    """
    o = check_points(bvh.mesh.name, "ray origin", origin, kind="mesh")
    d = check_points(bvh.mesh.name, "ray direction", direction, kind="mesh")
    if not max_t > 0:
        raise ValueError(f"ray max_t must be > 0 (got {max_t})")
    if matrix is not None:
        matrix, inv = world_frame(matrix, bvh.mesh.name)
        o, d = transform_points(inv, o), transform_vectors(inv[:3, :3], d)
    v = bvh.mesh.vertices
    lo, hi = v.min(axis=0), v.max(axis=0)
    far = np.linalg.norm(np.maximum(np.abs(o - lo), np.abs(o - hi)), axis=1)
    length = norm_rows(d)
    with np.errstate(divide="ignore"):
        reach = np.where(length > 0, 2.0 * far / length + 1.0, 1.0)
    reach = np.minimum(reach, max_t)
    t, tri_id, n_v, n_p = _first_hits(bvh, o, o + reach[:, None] * d)
    return _report(bvh, o, o + reach[:, None] * d, t, tri_id, n_v, n_p, matrix, reach)


def segment_triangle(p0: np.ndarray, p1: np.ndarray, tri: np.ndarray):
    """Batched exact segment-triangle test (see the module docstring for the conventions).

    Args:
        p0, p1: (n, 3) segment ends. tri: (n, 3, 3) triangles.

    Returns:
        (hit (n,) bool, t (n,) in [0, 1], meaningful where hit).
    """
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    s0, s1 = orient3d(a, b, c, p0), orient3d(a, b, c, p1)
    # ends not strictly on one side, and not both in the plane (grazing, not crossing)
    hit = (s0.astype(np.int64) * s1 <= 0) & ((s0 != 0) | (s1 != 0))
    t = np.zeros(len(p0))
    idx = np.nonzero(hit)[0]
    if len(idx):
        q0, q1, ta, tb, tc = p0[idx], p1[idx], a[idx], b[idx], c[idx]
        e = np.stack([orient3d(q0, q1, ta, tb), orient3d(q0, q1, tb, tc),
                      orient3d(q0, q1, tc, ta)], axis=1)
        inside = ~(np.any(e > 0, axis=1) & np.any(e < 0, axis=1)) & np.any(e != 0, axis=1)
        hit[idx] = inside
        d0 = orient3d_value(ta, tb, tc, q0)
        d1 = orient3d_value(ta, tb, tc, q1)
        denom = d0 - d1
        tt = np.where(denom != 0.0, d0 / np.where(denom != 0.0, denom, 1.0), 0.0)
        tt = np.where(s0[idx] == 0, 0.0, np.where(s1[idx] == 0, 1.0, tt))
        t[idx] = np.clip(tt, 0.0, 1.0)
    return hit, t


def _first_hits(bvh: BVH, p0: np.ndarray, p1: np.ndarray, cells: TriangleCells | None = None):
    n = len(p0)
    best_t = np.full(n, np.inf)
    best_tri = np.full(n, -1, dtype=np.int64)
    d = p1 - p0
    margin = PAD_REL * max(bvh.mesh.scale, float(np.abs(p0).max(initial=0.0)),
                           float(np.abs(p1).max(initial=0.0)), 1e-300)
    tri = bvh.ordered_triangles
    flat = bvh.mesh.degenerate[bvh.tri_order]
    seg = np.nonzero(np.any(p0 != p1, axis=1))[0]  # a point never crosses a plane: no hit
    n_v = n_p = 0
    if cells is not None and cells.usable and n:
        a, b = take(p0, seg), take(p1, seg)
        q, pos, rest = cells.candidates(np.minimum(a, b) - margin, np.maximum(a, b) + margin)
        n_v += len(seg) - len(rest)
        q, seg = seg[q], seg[rest]
        live = ~flat[pos]
        n_p += _pair_tests(bvh, q[live], pos[live], p0, p1, tri, best_t, best_tri)
    node = np.zeros(len(seg), dtype=np.int64)
    # axis-aligned boxes: a segment's own box culls with comparisons only; for a short one it
    # is nearly as selective as the exact slab test, which only long segments add
    boxes = bvh.kind.is_box
    if boxes:
        lo, hi = np.minimum(p0, p1) - margin, np.maximum(p0, p1) + margin
        short = norm_rows(d) <= SHORT * float(bvh.node_size[0])  # relative to the mesh's size
    while len(seg):
        keep = np.zeros(len(seg), dtype=bool)
        for s in range(0, len(seg), CHUNK):
            sl = slice(s, s + CHUNK)
            ss, nn = seg[sl], node[sl]
            bv = take(bvh.node_bv, nn)
            if boxes:
                k = np.all((take(lo, ss) <= bv[:, 3:]) & (bv[:, :3] <= take(hi, ss)), axis=1)
                slab = np.nonzero(k & ~short[ss])[0]
            else:
                k, slab = np.ones(len(ss), dtype=bool), np.arange(len(ss))
            if len(slab):
                t0, t1 = bvh.kind.ray_interval(bv[slab], p0[ss[slab]], d[ss[slab]], margin)
                k[slab] = (t0 <= t1) & (t1 >= 0.0) & (t0 <= np.minimum(best_t[ss[slab]], 1.0))
            keep[sl] = k
        n_v += len(seg)
        seg, node = seg[keep], node[keep]
        leaf = bvh.node_is_leaf[node]
        if leaf.any():
            n_p += _leaf_tests(bvh, seg[leaf], node[leaf], p0, p1, tri, flat, best_t, best_tri)
        kids = bvh.node_child[node[~leaf]]
        real = kids >= 0
        seg = np.repeat(seg[~leaf], real.sum(axis=1))
        node = kids[real]
    return best_t, best_tri, n_v, n_p


def _leaf_tests(bvh, seg, node, p0, p1, tri, flat, best_t, best_tri) -> int:
    count = bvh.node_tri_count[node]
    rep = np.repeat(np.arange(len(seg)), count)
    pos = bvh.node_first[node][rep] + np.arange(count.sum()) - np.repeat(np.cumsum(count) - count,
                                                                         count)
    s = seg[rep]
    live = ~flat[pos]
    return _pair_tests(bvh, s[live], pos[live], p0, p1, tri, best_t, best_tri)


def _pair_tests(bvh, s, pos, p0, p1, tri, best_t, best_tri) -> int:
    """Segments s (k,) against the triangles at leaf-order positions pos (k,): improves
    best_t and best_tri in place; returns k."""
    for c in range(0, len(s), CHUNK):
        sc, pc = s[c:c + CHUNK], pos[c:c + CHUNK]
        hit, t = segment_triangle(take(p0, sc), take(p1, sc), take(tri, pc))
        sc, pc, t = sc[hit], pc[hit], t[hit]
        tri_id = bvh.tri_order[pc]
        # earliest hit per segment (ties: lowest triangle id), then keep it if it is better
        o = np.lexsort((tri_id, t, sc))
        sc, t, tri_id = sc[o], t[o], tri_id[o]
        head = np.ones(len(sc), dtype=bool)
        head[1:] = sc[1:] != sc[:-1]
        sc, t, tri_id = sc[head], t[head], tri_id[head]
        better = (t < best_t[sc]) | ((t == best_t[sc]) & (tri_id < best_tri[sc]))
        best_t[sc[better]] = t[better]
        best_tri[sc[better]] = tri_id[better]
    return len(s)


def _report(bvh, p0, p1, t, tri_id, n_v, n_p, matrix, reach) -> SegmentHits:
    hit = tri_id >= 0
    n = len(p0)
    point = np.zeros((n, 3))
    normal = np.zeros((n, 3))
    front = np.zeros(n, dtype=bool)
    idx = np.nonzero(hit)[0]
    if len(idx):
        tv = bvh.mesh.triangle_vertices[tri_id[idx]]
        d = p1[idx] - p0[idx]
        point[idx] = p0[idx] + t[idx, None] * d
        if matrix is not None:  # report in world space; the winding normal of the mapped corners
            m = np.asarray(matrix, dtype=np.float64)
            point[idx] = transform_points(m, point[idx])
            tv = transform_points(m, tv.reshape(-1, 3)).reshape(-1, 3, 3)
            d = transform_vectors(m[:3, :3], d)
        face = cross(tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0])
        face /= norm_rows(face)[:, None]
        front[idx] = np.einsum("ij,ij->i", face, d) < 0.0
        normal[idx] = np.where(front[idx, None], face, -face)
    t_out = np.where(hit, t * reach, np.inf)
    return SegmentHits(hit, t_out, point, normal, front, tri_id, n_v, n_p, 0)
