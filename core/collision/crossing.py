"""Separation of a triangle from a point and of two segments over one step, batched over pairs:
whether the pair crossed during the step, which side it must be on, and the direction and gap
that separate it at the step's end.

Each primitive moves linearly from the step's start (``0``) to its end (``1``). A point and a
triangle cross when the point passes through the triangle: at a time the four are coplanar
(a root in [0, 1] of the cubic f(t) = (p - a) . ((b - a) x (c - a)), Provot's continuous test)
with the point inside the triangle then; two segments cross when at such a time of
(c - a) . ((b - a) x (d - c)) they meet. The side the pair must keep is the sign of f just
before its first crossing (the side it came from); a pair on the other side at the end
crossed and is separated along the end's plane (or common) normal back towards that side.
Any other pair is apart at the end on the side it has always been on, and is separated along
the line between its nearest points.

Every result names a ``normal``: the unit direction, at the end, from the second primitive
towards the first (the way the first must move to part them), and a ``gap``: the first's
nearest point minus the second's along it, negative for a crossed pair.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..transforms import (column_max, cross, divide_rows, dot_rows, norm_rows, row_any, row_max,
                          scale_rows, take, where_rows)
from .broadphase_base import keep_overlapping, transposed
from .broadphase_grid import (TooManyCandidates, UniformGrid, _auto_cell_size, _cell_ranges,
                              _entries, _keys)
from .distance import closest_on_triangles

PARALLEL = 1e-3  # sin of the angle below which two segments have no reliable common normal
TINY = 1e-12  # [m] nearest points closer than this give no direction
BISECTIONS = 40  # halvings of a crossing time's bracket
BRUTE_FORCE = 1 << 16  # box pairs below which all are tried
MEET = 1e-7  # of a primitive's size: as near as this at a root counts as meeting


class Separation(NamedTuple):
    """Pairs at the step's end (c of them).

    Attributes:
        weight: (c, k) weights of the first primitive's corners at its nearest point
            (barycentric for a triangle, (1 - s, s) for a segment).
        other: (c, 2) weights of the second's ends at its nearest point ((1, 0) for a point).
        normal: (c, 3) unit direction from the second towards the first.
        gap: (c,) separation along ``normal`` [m]; negative: they crossed.
        crossed: (c,) bool.
    """

    weight: np.ndarray
    other: np.ndarray
    normal: np.ndarray
    gap: np.ndarray
    crossed: np.ndarray


def barycentric(p: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(k, 3) barycentric weights of points p (k, 3) in triangles (k, 3, 3), clamped to the
    triangle; zero-area triangles weigh their corners equally."""
    a = corners[:, 0]
    e0, e1, e2 = corners[:, 1] - a, corners[:, 2] - a, p - a
    d00, d01, d11 = dot_rows(e0, e0), dot_rows(e0, e1), dot_rows(e1, e1)
    d20, d21 = dot_rows(e2, e0), dot_rows(e2, e1)
    denom = d00 * d11 - d01 * d01
    ok = denom > 0.0
    safe = np.where(ok, denom, 1.0)
    v = np.where(ok, (d11 * d20 - d01 * d21) / safe, 1.0 / 3.0)
    w = np.where(ok, (d00 * d21 - d01 * d20) / safe, 1.0 / 3.0)
    weights = np.clip(np.stack([1.0 - v - w, v, w], axis=1), 0.0, 1.0)
    return weights / weights.sum(axis=1, keepdims=True)


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    length = norm_rows(v)
    return divide_rows(v, np.where(length > 0.0, length, 1.0)), length


def _direction(diff: np.ndarray, fallback: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit ``diff`` rows, ``fallback`` where they are shorter than TINY; and the lengths."""
    unit, length = _unit(diff)
    return where_rows(length > TINY, unit, fallback), length


def _cubic(r0, dr, u0, du, w0, dw) -> tuple[np.ndarray, ...]:
    """Coefficients (k0, k1, k2, k3) of f(t) = r(t) . (u(t) x w(t)) for r = r0 + t dr etc."""
    c0, c2 = cross(u0, w0), cross(du, dw)
    c1 = cross(u0, dw) + cross(du, w0)
    return (dot_rows(r0, c0), dot_rows(r0, c1) + dot_rows(dr, c0),
            dot_rows(r0, c2) + dot_rows(dr, c1), dot_rows(dr, c2))


def _roots(k) -> tuple[np.ndarray, np.ndarray]:
    """Up to three roots in [0, 1] of cubics with coefficients k (each (c,)): (times (c, 3),
    nan where none, ascending; signs (c, 3) of f just before each root). The cubic is cut
    into monotone pieces at the roots of its derivative, and each piece whose ends differ in
    sign holds one root, found by bisection to BISECTIONS halvings."""
    k0, k1, k2, k3 = (c[:, None] for c in k)

    def f(t):
        return ((k3 * t + k2) * t + k1) * t + k0

    # critical points: 3 k3 t^2 + 2 k2 t + k1 = 0
    a, b, c = 3.0 * k3, 2.0 * k2, k1
    disc = b * b - 4.0 * a * c
    real = disc >= 0.0
    sq = np.sqrt(np.where(real, disc, 0.0))
    quadratic = np.abs(a) > 1e-300
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = np.where(quadratic, (-b - sq) / (2.0 * a), np.where(b != 0.0, -c / b, np.nan))
        t2 = np.where(quadratic, (-b + sq) / (2.0 * a), np.nan)
    crit = np.concatenate([np.where(real, t1, np.nan), np.where(real & quadratic, t2, np.nan)], 1)
    crit = np.where((crit > 0.0) & (crit < 1.0), crit, np.nan)
    ends = np.concatenate([np.zeros((len(k0), 1)), np.sort(crit, axis=1), np.ones((len(k0), 1))],
                          axis=1)
    # a missing critical point repeats the last end: an empty piece
    ends = np.fmax.accumulate(np.nan_to_num(ends, nan=-1.0), axis=1)
    lo, hi = ends[:, :-1], ends[:, 1:]
    f_lo, f_hi = f(lo), f(hi)
    has = (hi > lo) & ((f_lo < 0.0) != (f_hi < 0.0)) & (f_lo != 0.0)
    start_sign = np.sign(f_lo)
    times = np.full(lo.shape, np.nan)
    row, piece = np.nonzero(has)  # bisect only the pieces that hold a root
    if len(row):
        c = [x[row, 0] for x in (k0, k1, k2, k3)]
        lo, hi, sign = lo[row, piece], hi[row, piece], start_sign[row, piece]
        for _ in range(BISECTIONS):
            mid = 0.5 * (lo + hi)
            same = np.sign(((c[3] * mid + c[2]) * mid + c[1]) * mid + c[0]) == sign
            lo, hi = np.where(same, mid, lo), np.where(same, hi, mid)
        times[row, piece] = 0.5 * (lo + hi)
    return times, start_sign


def _first_crossing(times: np.ndarray, signs: np.ndarray, valid: np.ndarray, k):
    """Per pair: whether any root is a crossing (``valid``), and the sign (+1/-1) of f before
    the first (for a pair that never crossed: at the end, else at the start, else +1)."""
    valid = valid & np.isfinite(times)
    ever = row_any(valid)
    before = signs[np.arange(len(times)), np.argmax(valid, axis=1)]
    end, start = np.sign(sum(k)), np.sign(k[0])
    side = np.where(ever, before, np.where(end != 0.0, end, start))
    return ever, np.where(side != 0.0, side, 1.0)


def relative_motion(first: list, second: list) -> np.ndarray:
    """(c,) how far the distance between two groups of points' hulls can change when their
    points move by ``first`` and ``second`` (lists of (c, 3) [m] moves, one per point), each
    along a line: each group's largest point move, summed — seen from the still frame or from
    one moving with the pair's mean move, whichever is less. (The distance is the same seen
    from any frame moving along a line, and changes by at most each hull's largest point
    move; seen from the mean move's frame, a pair falling or swept along as a whole barely
    moves: two layers of a cloth falling at 2 m/s no longer each move by their whole fall.)"""
    moves = [*first, *second]
    mean = moves[0].copy()
    for move in moves[1:]:
        mean += move
    mean /= len(moves)
    still, carried = [], []
    for group in (first, second):
        most, most_carried = norm_rows(group[0]), norm_rows(group[0] - mean)
        for move in group[1:]:
            np.maximum(most, norm_rows(move), out=most)
            np.maximum(most_carried, norm_rows(move - mean), out=most_carried)
        still.append(most)
        carried.append(most_carried)
    return np.minimum(still[0] + still[1], carried[0] + carried[1])


def _may_have_met(apart: np.ndarray, motion: np.ndarray, size: np.ndarray) -> np.ndarray:
    """Rows of pairs ``apart`` [m] at the step's end that may have met during it: their
    distance changed by at most ``motion`` (their points' largest relative motion), and
    meeting counts within MEET of the primitives' largest ``size`` (with a margin for
    rounding). NaN rows may have."""
    return np.flatnonzero(~(apart > (1.0 + 1e-6) * (motion + MEET * size) + 2.0 * TINY))


def triangle_point(t0: np.ndarray, t1: np.ndarray, p0: np.ndarray,
                   p1: np.ndarray) -> Separation:
    """Triangles (c, 3, 3) against points (c, 3), at the step's start and end."""
    q, _, _ = closest_on_triangles(p1, t1)
    normal, apart = _unit(q - p1)  # (as _direction's where apart > TINY: every row not met)
    # as for segments (:func:`segment_segment`): a point further from the triangle at the end
    # than their relative motion over the step (and meeting's tolerance) cannot have met it
    motion = relative_motion([t1[:, k] - t0[:, k] for k in range(3)], [p1 - p0])
    size = np.sqrt(np.maximum(row_max(np.einsum("ckj,ckj->ck", t0 - t0[:, :1], t0 - t0[:, :1])),
                              row_max(np.einsum("ckj,ckj->ck", t1 - t1[:, :1], t1 - t1[:, :1]))))
    met = _may_have_met(apart, motion, size)
    crossed = np.zeros(len(p1), bool)
    if len(met):
        normal[met], crossed[met] = _moving_point(t0[met], t1[met], p0[met], p1[met], q[met])
    ones = np.zeros((len(p1), 2))
    ones[:, 0] = 1.0
    return Separation(barycentric(q, t1), ones, normal, dot_rows(q - p1, normal), crossed)


def _moving_point(t0, t1, p0, p1, q):
    """:func:`triangle_point`'s (normal, crossed) of pairs that may have met during the step,
    given the triangles' points q nearest the points at the end."""
    dt = t1 - t0
    k = _cubic(p0 - t0[:, 0], (p1 - p0) - dt[:, 0], t0[:, 1] - t0[:, 0], dt[:, 1] - dt[:, 0],
               t0[:, 2] - t0[:, 0], dt[:, 2] - dt[:, 0])
    times, signs = _roots(k)
    inside = np.zeros(times.shape, bool)
    row, r = np.nonzero(np.isfinite(times))
    if len(row):
        at = times[row, r][:, None]
        tri = t0[row] + at[:, :, None] * dt[row]
        point = p0[row] + at * (p1[row] - p0[row])
        # on the closed triangle (a root is exact to rounding: through an edge or a corner
        # counts, for every triangle there)
        size = np.sqrt(row_max(np.einsum("ckj,ckj->ck", tri - tri[:, :1], tri - tri[:, :1])))
        inside[row, r] = closest_on_triangles(point, tri)[1] <= (MEET * size) ** 2
    ever, side = _first_crossing(times, signs, inside, k)
    n1, _ = _unit(cross(t1[:, 1] - t1[:, 0], t1[:, 2] - t1[:, 0]))
    z1 = sum(k)  # f(1): the point's side of the triangle's winding at the end
    crossed = ever & (np.sign(z1) != side)
    plane = scale_rows(n1, -side)  # from the point towards the triangle, as it came
    normal, _ = _direction(q - p1, plane)
    normal = where_rows(crossed, plane, normal)
    # without a plane (zero area) or a direction: the start's
    flat = norm_rows(normal) == 0.0
    if flat.any():
        normal = where_rows(flat, _direction(t0.mean(axis=1) - p0,
                                             np.array([0.0, 0.0, 1.0]))[0], normal)
    return normal, crossed


def closest_on_segments(a, b, c, d) -> tuple[np.ndarray, np.ndarray]:
    """Parameters (s, t) in [0, 1] of the nearest points a + s (b - a) and c + t (d - c) of
    segments (m, 3) each (zero-length ones allowed); Ericson, Real-Time Collision Detection
    5.1.9."""
    d1, d2, r = b - a, d - c, a - c
    aa, ee, f = dot_rows(d1, d1), dot_rows(d2, d2), dot_rows(d2, r)
    cc, bb = dot_rows(d1, r), dot_rows(d1, d2)
    denom = aa * ee - bb * bb
    a_ok, e_ok = aa > 0.0, ee > 0.0
    skew = denom > 1e-14 * np.maximum(aa * ee, 1e-300)
    s = np.where(skew, np.clip((bb * f - cc * ee) / np.where(skew, denom, 1.0), 0.0, 1.0), 0.0)
    t = (bb * s + f) / np.where(e_ok, ee, 1.0)
    low, high = t < 0.0, t > 1.0
    s = np.where(low, np.clip(-cc / np.where(a_ok, aa, 1.0), 0.0, 1.0), s)
    s = np.where(high, np.clip((bb - cc) / np.where(a_ok, aa, 1.0), 0.0, 1.0), s)
    t = np.clip(t, 0.0, 1.0)
    # degenerate segments: a point's parameter is 0, the other segment's is its projection
    s = np.where(a_ok, s, 0.0)
    t = np.where(a_ok, t, np.clip(f / np.where(e_ok, ee, 1.0), 0.0, 1.0))
    s = np.where(a_ok & ~e_ok, np.clip(-cc / np.where(a_ok, aa, 1.0), 0.0, 1.0), s)
    t = np.where(e_ok, t, 0.0)
    return s, t


def segment_segment(a0, b0, c0, d0, a1, b1, c1, d1) -> Separation:
    """Segments a-b against segments c-d ((c, 3) each), at the step's start and end."""
    s, t = closest_on_segments(a1, b1, c1, d1)
    q = a1 + scale_rows(b1 - a1, s)
    p = c1 + scale_rows(d1 - c1, t)
    normal, apart = _unit(q - p)  # (as _direction's where apart > TINY: every row not met)
    # Over the step the segments' distance changes by at most their points' largest relative
    # motion: pairs further apart at the end than that (and than meeting's tolerance, with a
    # margin for rounding) cannot have met, and need no crossing test (most of a mesh resting
    # near another's edges: the same result, for a few of the operations)
    motion = relative_motion([a1 - a0, b1 - b0], [c1 - c0, d1 - d0])
    longest = np.maximum(np.maximum(norm_rows(b0 - a0), norm_rows(b1 - a1)),
                         np.maximum(norm_rows(d0 - c0), norm_rows(d1 - c1)))
    met = _may_have_met(apart, motion, longest)
    crossed = np.zeros(len(s), bool)
    if len(met):
        pick = (a0, b0, c0, d0, a1, b1, c1, d1, s, t, q, p)
        normal[met], crossed[met] = _moving_segments(*(x[met] for x in pick))
    return Separation(np.stack([1.0 - s, s], axis=1), np.stack([1.0 - t, t], axis=1), normal,
                      dot_rows(q - p, normal), crossed)


def _moving_segments(a0, b0, c0, d0, a1, b1, c1, d1, s, t, q, p):
    """:func:`segment_segment`'s (normal, crossed) of pairs that may have met during the step,
    given their nearest points at the end (parameters s, t; points q, p)."""
    da, db, dc, dd = a1 - a0, b1 - b0, c1 - c0, d1 - d0
    # f = (c - a) . ((b - a) x (d - c)) = -(a - c) . m: its sign is minus the first's side
    k = _cubic(c0 - a0, dc - da, b0 - a0, db - da, d0 - c0, dd - dc)
    times, signs = _roots(k)
    meet = np.zeros(times.shape, bool)
    row, r = np.nonzero(np.isfinite(times))
    if len(row):
        at = times[row, r]  # (rows by columns: numpy broadcasts (k, 1) over (k, 3) slowly)
        a, b = a0[row] + scale_rows(da[row], at), b0[row] + scale_rows(db[row], at)
        c, d = c0[row] + scale_rows(dc[row], at), d0[row] + scale_rows(dd[row], at)
        sr, tr = closest_on_segments(a, b, c, d)
        gap = norm_rows(a + scale_rows(b - a, sr) - c - scale_rows(d - c, tr))
        scale = np.maximum(norm_rows(b - a), norm_rows(d - c))
        meet[row, r] = gap <= MEET * scale
    ever, before = _first_crossing(times, signs, meet, k)
    side = -before
    m1, length = _unit(cross(b1 - a1, d1 - c1))
    reliable = length > PARALLEL * norm_rows(b1 - a1) * norm_rows(d1 - c1)
    crossed = ever & reliable & (-np.sign(sum(k)) != side)
    plane = scale_rows(m1, side)
    s0, t0 = closest_on_segments(a0, b0, c0, d0)
    before_dir, _ = _direction(a0 + scale_rows(b0 - a0, s0) - c0 - scale_rows(d0 - c0, t0),
                               np.array([0.0, 0.0, 1.0]))
    normal, _ = _direction(q - p, where_rows(reliable, plane, before_dir))
    return where_rows(crossed, plane, normal), crossed


def box_pairs(lo_a: np.ndarray, hi_a: np.ndarray, lo_b: np.ndarray,
              hi_b: np.ndarray, max_candidates: int | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
    """Every overlapping (closed) pair of a box of A (n, 3) and a box of B (m, 3): indices
    (i into A, j into B), sorted by i. Few pairs to try (n m <= BRUTE_FORCE): all of them;
    else a uniform grid of B's boxes looked up by A's (:func:`_across_cells`), which raises
    :class:`~.broadphase_grid.TooManyCandidates` before making more than ``max_candidates``
    candidate pairs (None: any number)."""
    if not len(lo_a) or not len(lo_b):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    if len(lo_a) * len(lo_b) <= BRUTE_FORCE:
        i, j = np.nonzero(np.all((lo_a[:, None] <= hi_b[None]) & (lo_b[None] <= hi_a[:, None]),
                                 axis=2))
        return i, j
    lo, hi = np.concatenate([lo_a, lo_b]), np.concatenate([hi_a, hi_b])
    cell_lo, cell_hi = _cell_ranges(lo, hi, _auto_cell_size(lo, hi))
    return _across_cells(lo, hi, len(lo_a), cell_lo, cell_hi - cell_lo + 1,
                         column_max(cell_hi) + 1, max_candidates)


def element_boxes(low: np.ndarray, high: np.ndarray, ids: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Boxes (m, 3) of elements ``ids`` (m, k) — triangles, edges — of points whose own boxes
    are low, high (n, 3): k gathers (``np.take``: 3 x faster than fancy indexing of rows), not
    a reduction over an (m, k, 3) copy."""
    lo, hi = take(low, ids[:, 0]), take(high, ids[:, 0])
    for c in range(1, ids.shape[1]):
        np.minimum(lo, take(low, ids[:, c]), out=lo)
        np.maximum(hi, take(high, ids[:, c]), out=hi)
    return lo, hi


def _across_cells(lo, hi, count_a: int, cell_lo, extent, dims,
                  max_candidates: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Box pairs across the sets A (the first ``count_a`` boxes of lo, hi) and B (the rest)
    through one uniform grid of B's boxes, looked up by A's: no pair within a set is ever
    formed (a cloth's neighbouring triangles all overlap). Each pair is kept from one cell,
    the first both boxes share (max of their first cells), then tested exactly; a box spanning
    more than the grid's max_cells_per_box cells is tried against the whole other set."""
    large = extent.prod(axis=1, dtype=np.float64) > UniformGrid().max_cells_per_box
    box_b, cell_b = _entries(count_a + np.flatnonzero(~large[count_a:]), cell_lo, extent)
    box_a, cell_a = _entries(np.flatnonzero(~large[:count_a]), cell_lo, extent)
    key_b, hashed = _keys(cell_b, dims)
    key_a, _ = _keys(cell_a, dims)
    order = np.argsort(key_b, kind="stable")
    key_b, box_b, cell_b = key_b[order], box_b[order], cell_b[:, order]
    first = np.searchsorted(key_b, key_a, side="left")
    count = np.searchsorted(key_b, key_a, side="right") - first
    if max_candidates is not None:
        big = int(large[:count_a].sum()), int(large[count_a:].sum())
        candidates = int(count.sum()) + big[0] * (len(lo) - count_a) + \
            (count_a - big[0]) * big[1]
        if candidates > max_candidates:
            raise TooManyCandidates(candidates, len(lo), max_candidates)
    entry = np.repeat(np.arange(len(key_a)), count)
    at = np.repeat(first - np.cumsum(count) + count, count) + np.arange(int(count.sum()))
    i, j = box_a[entry], box_b[at]
    keep = np.ones(len(i), bool)
    for a in range(3):
        keep &= np.maximum(cell_lo[i, a], cell_lo[j, a]) == cell_a[a, entry]
        if hashed:  # one hash bucket may hold several cells
            keep &= cell_b[a, at] == cell_a[a, entry]
    # a box spanning many cells (rare) is tried against every box of the other set
    big_a, big_b = np.flatnonzero(large[:count_a]), count_a + np.flatnonzero(large[count_a:])
    small_a = np.flatnonzero(~large[:count_a])
    every_b = np.arange(count_a, len(lo))
    i = np.concatenate([i[keep], np.repeat(big_a, len(every_b)),
                        np.tile(small_a, len(big_b))])
    j = np.concatenate([j[keep], np.tile(every_b, len(big_a)), np.repeat(big_b, len(small_a))])
    lo_t, hi_t = transposed(lo, hi)
    i, j = keep_overlapping(lo_t, hi_t, i, j)
    order = np.lexsort((j, i))
    return i[order], j[order] - count_a


def __getattr__(name: str):
    """KeptPairs and KeptTests, which moved to :mod:`.kept`: a checkpoint pickled before names
    them here (imported on first use: :mod:`.kept` imports this module)."""
    if name in ("KeptPairs", "KeptTests"):
        from . import kept
        return getattr(kept, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
