"""Exact triangle-triangle overlap test, batched over pairs.

Triangles are closed sets: touching at a single point, along an edge, or lying in the same plane
with overlapping areas all count as overlap. The answer is exact for the given floating-point
coordinates: every decision is the sign of an orientation determinant from
:mod:`.predicates` (double precision with a certified error bound, exact integer arithmetic when
the bound cannot decide), and no epsilon is ever compared against.

The general case follows Guigue & Devillers ("Fast and robust triangle-triangle overlap test
using orientation predicates", 2003): reject when one triangle lies strictly on one side of the
other's plane; otherwise put both triangles in a canonical vertex order (vertex p alone on the
non-negative side of the other plane, q and r on the non-positive side) in which the two
segments the triangles cut from the planes' common line overlap exactly when two more
orientations are non-positive. The cases that method excludes are handled separately, exactly:

* coplanar triangles: 2D overlap of the convex hulls in a projection onto a coordinate plane;
* degenerate (zero-area) triangles, which are segments or points: segment-triangle and
  segment-segment tests.

2D hull overlap of two 3-point sets (possibly degenerate) is: a vertex of one inside the other's
hull, or an edge of one crossing an edge of the other. Where no single projection is known to be
one-to-one on the points' common plane (two degenerate triangles), the 2D test must hold in all
three coordinate projections: a projection never separates intersecting sets, and at least one
of the three is one-to-one on any plane.
"""
from __future__ import annotations

from itertools import product

import numpy as np

from .predicates import orient2d, orient3d

_NEXT = np.array([1, 2, 0])


def _canonical_table() -> tuple[np.ndarray, np.ndarray]:
    """For each sign pattern of a triangle's vertices against the other plane (27 codes):
    the vertex to rotate to the front (the apex) and whether that plane must be flipped so the
    apex is on its non-negative side and the other two on its non-positive side."""
    apex = np.full(27, -1, dtype=np.int64)
    flip = np.zeros(27, dtype=bool)
    for code, s in enumerate(product((-1, 0, 1), repeat=3)):
        if all(x == 0 for x in s) or all(x > 0 for x in s) or all(x < 0 for x in s):
            continue
        choices = [(i, f) for f in (1, -1) for i in range(3)
                   if f * s[i] >= 0 and f * s[(i + 1) % 3] <= 0 and f * s[(i + 2) % 3] <= 0]
        choices.sort(key=lambda c: c[1] * s[c[0]] == 0)  # prefer an apex off the plane
        apex[code], flip[code] = choices[0][0], choices[0][1] < 0
    apex.setflags(write=False)
    flip.setflags(write=False)
    return apex, flip


_APEX, _FLIP = _canonical_table()


def triangles_overlap(tri_a: np.ndarray, tri_b: np.ndarray) -> np.ndarray:
    """Whether each pair of closed triangles intersects (exactly; see the module docstring).

    Args:
        tri_a: (n, 3, 3) vertices of the first triangle of each pair [m].
        tri_b: (n, 3, 3) vertices of the second triangle of each pair [m].

    Returns:
        (n,) bool.

    Raises:
        ValueError: shapes differ from (n, 3, 3) or a coordinate is not finite.
    """
    tri_a = np.asarray(tri_a, dtype=np.float64)
    tri_b = np.asarray(tri_b, dtype=np.float64)
    if tri_a.ndim != 3 or tri_a.shape[1:] != (3, 3) or tri_b.shape != tri_a.shape:
        raise ValueError(f"triangle pairs must be two (n, 3, 3) arrays "
                         f"(got {tri_a.shape} and {tri_b.shape})")
    for name, tri in (("first", tri_a), ("second", tri_b)):
        bad = ~np.isfinite(tri).all(axis=(1, 2))
        if bad.any():
            i = int(np.argmax(bad))
            raise ValueError(f"{name} triangle of pair {i} has a non-finite vertex: "
                             f"{tri[i].tolist()}")
    out = np.zeros(len(tri_a), dtype=bool)
    # exact prefilter: disjoint axis-aligned bounds (plain comparisons of the inputs)
    box = (np.all(_corner_min(tri_a) <= _corner_max(tri_b), axis=1)
           & np.all(_corner_min(tri_b) <= _corner_max(tri_a), axis=1))
    idx = np.nonzero(box)[0]
    if len(idx) == 0:
        return out
    a, b = tri_a[idx], tri_b[idx]
    na, nb = normal_signs(a), normal_signs(b)
    flat_a, flat_b = ~na.any(axis=1), ~nb.any(axis=1)
    sel = ~flat_a & ~flat_b
    out[idx[sel]] = _proper(a[sel], b[sel], na[sel])
    sel = ~flat_a & flat_b
    out[idx[sel]] = _segment_triangle(_extent(b[sel]), a[sel], na[sel])
    sel = flat_a & ~flat_b
    out[idx[sel]] = _segment_triangle(_extent(a[sel]), b[sel], nb[sel])
    sel = flat_a & flat_b
    out[idx[sel]] = _segment_segment(_extent(a[sel]), _extent(b[sel]))
    return out


def _corner_min(tri: np.ndarray) -> np.ndarray:
    return np.minimum(np.minimum(tri[:, 0], tri[:, 1]), tri[:, 2])


def _corner_max(tri: np.ndarray) -> np.ndarray:
    return np.maximum(np.maximum(tri[:, 0], tri[:, 1]), tri[:, 2])


def normal_signs(tri: np.ndarray) -> np.ndarray:
    """Exact signs of the components of each triangle's normal (b - a) x (c - a).

    Component k is the 2D orientation of the triangle projected along axis k onto the
    coordinates (k + 1, k + 2) mod 3. A triangle has zero area exactly when all three vanish.

    Args:
        tri: (n, 3, 3) vertices.

    Returns:
        (n, 3) int8.
    """
    out = np.empty((len(tri), 3), dtype=np.int8)
    for k in range(3):
        p = _project(tri, k)
        out[:, k] = orient2d(p[:, 0], p[:, 1], p[:, 2])
    return out


def _project(points: np.ndarray, k) -> np.ndarray:
    """Drop coordinate k (scalar or per-row (n,)) of (n, m, 3) points, keeping (k+1, k+2) mod 3."""
    k = np.asarray(k)
    if k.ndim == 0:
        return points[..., [(int(k) + 1) % 3, (int(k) + 2) % 3]]
    cols = np.stack([(k + 1) % 3, (k + 2) % 3], axis=1)
    return np.take_along_axis(points, cols[:, None, :], axis=2)


def _extent(tri: np.ndarray) -> np.ndarray:
    """(n, 2, 3) end points of degenerate (collinear) triangles: the extreme pair along the axis
    of largest spread (both the same point when the three vertices coincide)."""
    rows = np.arange(len(tri))
    axis = np.argmax(tri.max(axis=1) - tri.min(axis=1), axis=1)
    coord = tri[rows, :, axis]
    return np.stack([tri[rows, np.argmin(coord, axis=1)], tri[rows, np.argmax(coord, axis=1)]],
                    axis=1)


def _sides(tri: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n, m) signs of (n, m, 3) points against the plane of (n, 3, 3) triangles."""
    return np.stack([orient3d(tri[:, 0], tri[:, 1], tri[:, 2], points[:, i])
                     for i in range(points.shape[1])], axis=1)


def _one_side(s: np.ndarray) -> np.ndarray:
    return np.all(s > 0, axis=1) | np.all(s < 0, axis=1)


def _proper(a: np.ndarray, b: np.ndarray, na: np.ndarray) -> np.ndarray:
    """Overlap of non-degenerate triangle pairs (n, 3, 3); ``na`` are a's normal signs."""
    out = np.zeros(len(a), dtype=bool)
    s_ab = _sides(b, a)  # a's vertices against b's plane
    live = np.nonzero(~_one_side(s_ab))[0]
    s_ba = _sides(a[live], b[live])
    keep = ~_one_side(s_ba)
    live, s_ba = live[keep], s_ba[keep]
    coplanar = np.all(s_ab[live] == 0, axis=1)
    cop = live[coplanar]
    if len(cop):
        axis = np.argmax(np.abs(na[cop]), axis=1)  # a's plane is not parallel to that axis
        out[cop] = hulls_overlap_2d(_project(a[cop], axis), _project(b[cop], axis))
    gen = live[~coplanar]
    if len(gen):
        out[gen] = _canonical_overlap(a[gen], b[gen], s_ab[gen], s_ba[~coplanar])
    return out


def _code(s: np.ndarray) -> np.ndarray:
    return (s[:, 0].astype(np.int64) + 1) * 9 + (s[:, 1] + 1) * 3 + (s[:, 2] + 1)


def _canonical_overlap(a, b, s_ab, s_ba) -> np.ndarray:
    """Guigue-Devillers decision for non-coplanar pairs that both straddle the other's plane."""
    rows = np.arange(len(a))[:, None]
    order = np.array([0, 1, 2])
    code = _code(s_ab)
    apex, flip = _APEX[code], _FLIP[code]
    a = a[rows, (apex[:, None] + order) % 3]  # rotation keeps a's plane orientation
    swap = np.where(flip[:, None], [0, 2, 1], order)  # flipping b's plane = swapping q2, r2
    b = b[rows, swap]
    s_ba = s_ba[rows, swap]
    code = _code(s_ba)
    apex, flip = _APEX[code], _FLIP[code]
    b = b[rows, (apex[:, None] + order) % 3]
    a = a[rows, np.where(flip[:, None], [0, 2, 1], order)]
    p1, q1, r1 = a[:, 0], a[:, 1], a[:, 2]
    p2, q2, r2 = b[:, 0], b[:, 1], b[:, 2]
    # the segments a and b cut from the planes' common line, [i, j] and [k, l], overlap
    # exactly when k <= j and i <= l; these are those two comparisons as orientations
    return (orient3d(q1, p2, p1, q2) <= 0) & (orient3d(p1, p2, r1, r2) <= 0)


def _segment_triangle(seg: np.ndarray, tri: np.ndarray, nt: np.ndarray) -> np.ndarray:
    """Closed segments (n, 2, 3) (possibly points) against non-degenerate triangles (n, 3, 3)."""
    out = np.zeros(len(seg), dtype=bool)
    s = _sides(tri, seg)
    live = np.nonzero(~_one_side(s))[0]
    coplanar = np.all(s[live] == 0, axis=1)
    cop = live[coplanar]
    if len(cop):
        axis = np.argmax(np.abs(nt[cop]), axis=1)
        as_tri = seg[cop][:, [0, 1, 1]]
        out[cop] = hulls_overlap_2d(_project(tri[cop], axis), _project(as_tri, axis))
    gen = live[~coplanar]
    if len(gen):
        u, v, t = seg[gen, 0], seg[gen, 1], tri[gen]
        e = np.stack([orient3d(u, v, t[:, i], t[:, _NEXT[i]]) for i in range(3)], axis=1)
        out[gen] = ~(np.any(e > 0, axis=1) & np.any(e < 0, axis=1))
    return out


def _segment_segment(s1: np.ndarray, s2: np.ndarray) -> np.ndarray:
    """Closed segments (n, 2, 3) (possibly points) against each other."""
    out = np.zeros(len(s1), dtype=bool)
    cop = np.nonzero(orient3d(s1[:, 0], s1[:, 1], s2[:, 0], s2[:, 1]) == 0)[0]
    if len(cop):
        t1, t2 = s1[cop][:, [0, 1, 1]], s2[cop][:, [0, 1, 1]]
        hit = np.ones(len(cop), dtype=bool)
        for k in range(3):  # no single projection is known to be one-to-one: all must agree
            hit &= hulls_overlap_2d(_project(t1, k), _project(t2, k))
        out[cop] = hit
    return out


# --- 2D ----------------------------------------------------------------------------------------

def hulls_overlap_2d(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Whether the convex hulls of two 3-point sets in the plane intersect (exact, closed).

    Works for degenerate sets (collinear or coincident points).

    Args:
        p, q: (n, 3, 2) points.

    Returns:
        (n,) bool.
    """
    hit = np.zeros(len(p), dtype=bool)
    for i in range(3):
        hit |= _point_in_hull(p[:, i], q) | _point_in_hull(q[:, i], p)
    for i in range(3):
        for j in range(3):
            hit |= _segments_meet(p[:, i], p[:, _NEXT[i]], q[:, j], q[:, _NEXT[j]])
    return hit


def _point_in_hull(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Point (n, 2) in the closed hull of (n, 3, 2) points. For a non-degenerate triangle: no two
    edge orientations of opposite strict sign. For collinear points the edge orientations of a
    point off their line always have opposite signs, and on it they are all zero: then the
    point is inside exactly when it lies within the points' bounding box."""
    o = np.stack([orient2d(t[:, i], t[:, _NEXT[i]], x) for i in range(3)], axis=1)
    mixed = np.any(o > 0, axis=1) & np.any(o < 0, axis=1)
    on_line = np.all(o == 0, axis=1)
    in_box = np.all((x >= t.min(axis=1)) & (x <= t.max(axis=1)), axis=1)
    return ~mixed & (~on_line | in_box)


def _segments_meet(a, b, c, d) -> np.ndarray:
    """Closed 2D segments ab and cd (n, 2) (possibly points) intersect."""
    o1, o2 = orient2d(a, b, c), orient2d(a, b, d)
    o3, o4 = orient2d(c, d, a), orient2d(c, d, b)
    collinear = (o1 == 0) & (o2 == 0) & (o3 == 0) & (o4 == 0)
    boxes = np.all((np.maximum(np.minimum(a, b), np.minimum(c, d))
                    <= np.minimum(np.maximum(a, b), np.maximum(c, d))), axis=1)
    crossing = (o1 * o2 <= 0) & (o3 * o4 <= 0)
    return np.where(collinear, boxes, crossing)
