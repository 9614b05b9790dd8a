"""Continuous crossing of a point and a triangle, and of two segments, over a step
(:mod:`physanim.core.collision.crossing`), against brute force: the pair's coplanarity
function sampled at 20,000 times, every sign change located and tested for the point being in
the triangle (the segments meeting) there. Pairs whose answer hangs on rounding (a sampled
crossing within 1e-4 of the triangle's boundary, the segments' ends, or an end on the plane)
are left out; the rest must agree exactly. Also: the box pairing against all pairs, the creases
of meshes, and the colouring of constraints on three points."""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.collision.crossing import (box_pairs, closest_on_segments, relative_motion,
                                              segment_segment, triangle_point)
from physanim.core.collision.kept import KeptPairs, KeptTests
from physanim.core.errors import PhysanimError
from physanim.core.collision.mesh import TriangleMesh
from physanim.core.collision.shapes import box_mesh, cylinder_mesh
from physanim.core.colouring import colour
from physanim.tests.core.helpers import grid

SAMPLES = 20_000
MARGIN = 1e-4


def _lerp(a0, a1, t):
    return a0 + t * (a1 - a0)


def _bary(p, a, b, c):
    """Unclamped barycentric weights of p in triangle abc (3, 3 arrays)."""
    m = np.stack([b - a, c - a], axis=1)
    uv = np.linalg.lstsq(m, p - a, rcond=None)[0]
    return np.array([1.0 - uv.sum(), uv[0], uv[1]])


def _truth_point(t0, t1, p0, p1):
    """(crossed, decided): brute force for one pair."""
    ts = np.linspace(0.0, 1.0, SAMPLES + 1)
    tri = t0[None] + ts[:, None, None] * (t1 - t0)[None]
    p = p0[None] + ts[:, None] * (p1 - p0)[None]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    f = np.einsum("ij,ij->i", p - tri[:, 0], n)
    if abs(f[0]) < 1e-9 or abs(f[-1]) < 1e-9:
        return False, False
    change = np.nonzero(np.sign(f[1:]) != np.sign(f[:-1]))[0]
    for k in change:
        t = ts[k] + (ts[k + 1] - ts[k]) * f[k] / (f[k] - f[k + 1])
        w = _bary(_lerp(p0, p1, t), *_lerp(t0, t1, t))
        if abs(w.min()) < MARGIN:
            return False, False
        if w.min() > 0.0:
            return bool(np.sign(f[-1]) != np.sign(f[k])), True
    return False, True


def _truth_segments(a0, b0, c0, d0, a1, b1, c1, d1):
    ts = np.linspace(0.0, 1.0, SAMPLES + 1)[:, None]
    a, b, c, d = (_lerp(u, w, ts) for u, w in ((a0, a1), (b0, b1), (c0, c1), (d0, d1)))
    f = np.einsum("ij,ij->i", c - a, np.cross(b - a, d - c))
    if abs(f[0]) < 1e-9 or abs(f[-1]) < 1e-9:
        return False, False
    change = np.nonzero(np.sign(f[1:]) != np.sign(f[:-1]))[0]
    for k in change:
        t = ts[k, 0] + (ts[k + 1, 0] - ts[k, 0]) * f[k] / (f[k] - f[k + 1])
        s, u = closest_on_segments(*(_lerp(x0, x1, t)[None] for x0, x1 in
                                     ((a0, a1), (b0, b1), (c0, c1), (d0, d1))))
        if min(s[0], 1 - s[0], u[0], 1 - u[0]) < MARGIN:
            return False, False
        return bool(np.sign(f[-1]) != np.sign(f[k])), True
    return False, True


def _agreed(crossed: np.ndarray, truth, cases) -> tuple[int, int]:
    """Each case's crossing against brute force ``truth(*case) -> (crossed, decided)``:
    (cases decided, of them crossed); every decided one must agree."""
    decided = count = 0
    for i, case in enumerate(cases):
        answer, ok = truth(*case)
        if ok:
            decided += 1
            count += answer
            assert crossed[i] == answer, i
    return decided, count


def test_point_triangle_crossings_agree_with_brute_force():
    rng = np.random.default_rng(4)
    count = 800
    t0 = rng.normal(size=(count, 3, 3))
    t1 = t0 + 0.7 * rng.normal(size=(count, 3, 3))
    p0 = t0.mean(axis=1) + rng.normal(size=(count, 3))
    p1 = p0 + 1.5 * rng.normal(size=(count, 3))
    sep = triangle_point(t0, t1, p0, p1)
    decided, crossed = _agreed(sep.crossed, _truth_point, zip(t0, t1, p0, p1))
    assert decided > 600 and crossed > 20  # the sample holds both answers
    # a crossed pair's gap is minus the point's distance behind the plane, its normal the
    # plane's, pointing from the point back to where the triangle was
    i = np.nonzero(sep.crossed)[0]
    n = np.cross(t1[i, 1] - t1[i, 0], t1[i, 2] - t1[i, 0])
    n /= np.linalg.norm(n, axis=1)[:, None]
    assert np.allclose(np.abs(np.einsum("ij,ij->i", sep.normal[i], n)), 1.0)
    assert np.allclose(sep.gap[i], -np.abs(np.einsum("ij,ij->i", p1[i] - t1[i, 0], n)))


def test_segment_crossings_agree_with_brute_force():
    rng = np.random.default_rng(5)
    count = 800
    ends0 = rng.normal(size=(count, 4, 3))
    ends1 = ends0 + 0.8 * rng.normal(size=(count, 4, 3))
    sep = segment_segment(*(ends0[:, k] for k in range(4)), *(ends1[:, k] for k in range(4)))
    decided, crossed = _agreed(sep.crossed, _truth_segments,
                               (np.concatenate([e0, e1]) for e0, e1 in zip(ends0, ends1)))
    assert decided > 500 and crossed > 20


def test_segments_too_far_apart_to_meet_skip_the_crossing_test_with_the_same_answer(
        monkeypatch):
    """A mesh resting near another's edges: pairs a few millimetres apart moving by about as
    much. Those further apart at the end than their points' relative motion cannot have met;
    they are answered from their nearest points at the end (never crossed; the normal from the
    second's nearest point to the first's, the gap their distance) without the crossing test —
    and crossings among the others still agree with brute force."""
    from physanim.core.collision import crossing
    rng = np.random.default_rng(11)
    count = 600
    ends0 = rng.normal(size=(count, 4, 3)) * 0.02
    ends0[:, 2:] += ends0[:, :2].mean(axis=1)[:, None] - ends0[:, 2:].mean(axis=1)[:, None] + \
        rng.normal(size=(count, 1, 3)) * 0.004  # the second segment across the first's middle
    ends1 = ends0 + rng.normal(size=(count, 4, 3)) * rng.choice([1e-4, 1e-3, 4e-3], (count, 1, 1))
    tested = []
    moving = crossing._moving_segments
    monkeypatch.setattr(crossing, "_moving_segments",
                        lambda *a: tested.append(len(a[0])) or moving(*a))
    sep = segment_segment(*(ends0[:, k] for k in range(4)), *(ends1[:, k] for k in range(4)))
    assert 0 < sum(tested) < 0.7 * count  # many pairs skip it, not all
    decided, crossed = _agreed(sep.crossed, _truth_segments,
                               (np.concatenate([e0, e1]) for e0, e1 in zip(ends0, ends1)))
    assert decided > 500 and crossed > 5
    a1, b1, c1, d1 = (ends1[:, k] for k in range(4))
    s, t = closest_on_segments(a1, b1, c1, d1)
    diff = (a1 + s[:, None] * (b1 - a1)) - (c1 + t[:, None] * (d1 - c1))
    apart = np.linalg.norm(diff, axis=1)
    far = ~sep.crossed
    assert np.allclose(sep.gap[far], apart[far], rtol=1e-12, atol=0.0)
    assert np.allclose(sep.normal[far], diff[far] / apart[far, None], rtol=0.0, atol=1e-12)
    # brute force: every pair that skipped the test stays apart throughout the step
    ts = np.linspace(0.0, 1.0, 201)
    lows = []
    for tt in ts:
        e = ends0 + tt * (ends1 - ends0)
        u, w = closest_on_segments(e[:, 0], e[:, 1], e[:, 2], e[:, 3])
        lows.append(np.linalg.norm(e[:, 0] + u[:, None] * (e[:, 1] - e[:, 0]) - e[:, 2]
                                   - w[:, None] * (e[:, 3] - e[:, 2]), axis=1))
    motion = np.maximum(*(np.linalg.norm(ends1[:, k] - ends0[:, k], axis=1) for k in (0, 1))) + \
        np.maximum(*(np.linalg.norm(ends1[:, k] - ends0[:, k], axis=1) for k in (2, 3)))
    skipped = apart > 1.01 * motion + 1e-9
    assert skipped.sum() > 0.3 * count
    assert (np.min(lows, axis=0)[skipped] > 0.0).all()


def test_points_too_far_from_a_triangle_to_meet_it_skip_the_crossing_test(monkeypatch):
    """A mesh resting on another's faces: points a few millimetres from triangles, moving by
    about as much. Those further away at the end than the pair's relative motion cannot have
    met the triangle; they are answered from the nearest point at the end without the
    crossing test — and crossings among the others still agree with brute force."""
    from physanim.core.collision import crossing
    from physanim.core.collision.distance import closest_on_triangles
    rng = np.random.default_rng(12)
    count = 600
    t0 = rng.normal(size=(count, 3, 3)) * 0.03
    p0 = t0.mean(axis=1) + rng.normal(size=(count, 3)) * 0.004
    step = rng.choice([1e-4, 1e-3, 4e-3], (count, 1))
    t1 = t0 + rng.normal(size=(count, 3, 3)) * step[:, :, None]
    p1 = p0 + rng.normal(size=(count, 3)) * step
    tested = []
    moving = crossing._moving_point
    monkeypatch.setattr(crossing, "_moving_point",
                        lambda *a: tested.append(len(a[0])) or moving(*a))
    sep = triangle_point(t0, t1, p0, p1)
    assert 0 < sum(tested) < 0.7 * count  # many pairs skip it, not all
    decided, crossed = _agreed(sep.crossed, _truth_point, zip(t0, t1, p0, p1))
    assert decided > 500 and crossed > 5
    q = closest_on_triangles(p1, t1)[0]
    apart = np.linalg.norm(q - p1, axis=1)
    far = ~sep.crossed
    assert np.allclose(sep.gap[far], apart[far], rtol=1e-12, atol=0.0)
    assert np.allclose(sep.normal[far], (q - p1)[far] / apart[far, None], rtol=0.0, atol=1e-12)
    # brute force: the pairs far enough apart never touch during the step
    lows = [np.linalg.norm(closest_on_triangles(p0 + tt * (p1 - p0), t0 + tt * (t1 - t0))[0]
                           - (p0 + tt * (p1 - p0)), axis=1) for tt in np.linspace(0, 1, 201)]
    motion = np.linalg.norm(p1 - p0, axis=1) + np.linalg.norm(t1 - t0, axis=2).max(axis=1)
    skipped = apart > 1.01 * motion + 1e-9
    assert skipped.sum() > 0.3 * count
    assert (np.min(lows, axis=0)[skipped] > 0.0).all()


def test_relative_motion_is_the_largest_move_of_each_group_from_the_mean_move():
    rng = np.random.default_rng(20)
    first, second = rng.normal(size=(50, 3, 3)), rng.normal(size=(50, 1, 3))
    mean = np.concatenate([first, second], axis=1).mean(axis=1)[:, None]
    carried = np.linalg.norm(first - mean, axis=2).max(axis=1) + \
        np.linalg.norm(second - mean, axis=2).max(axis=1)
    still = np.linalg.norm(first, axis=2).max(axis=1) + np.linalg.norm(second[:, 0], axis=1)
    got = relative_motion(list(first.transpose(1, 0, 2)), list(second.transpose(1, 0, 2)))
    assert np.allclose(got, np.minimum(still, carried), rtol=1e-14, atol=0.0)
    assert (carried < still).any() and (still < carried).any()  # (both frames chosen here)
    # nothing for a pair moving as one
    same = [np.tile([0.3, -2.0, 0.1], (4, 1))] * 2
    assert np.allclose(relative_motion(same, same[:1]), 0.0, rtol=0.0, atol=1e-15)


@pytest.mark.parametrize("kind", ["point", "segments"])
def test_pairs_carried_along_together_skip_the_crossing_test_and_answer_as_if_held(
        kind, monkeypatch):
    """Two layers of a falling cloth: each pair moves 4 cm in the sub-step, but hardly against
    itself. Their distance is the same seen from a frame moving with the pair's mean move, so
    a pair further apart at the end than its points' motion relative to that mean cannot have
    met: the crossing test is skipped for as many pairs as when the common move is taken
    away (every pair was tested before: their whole moves exceed their gaps), and the
    answers, crossings included, are the same."""
    from physanim.core.collision import crossing
    rng = np.random.default_rng(21)
    count = 500
    step = rng.choice([1e-4, 1e-3, 4e-3], (count, 1, 1))
    if kind == "point":
        start = rng.normal(size=(count, 4, 3)) * 0.03  # a triangle and a point over it
        start[:, 3] = start[:, :3].mean(axis=1) + rng.normal(size=(count, 3)) * 0.004
        name = "_moving_point"

        def test(e0, e1):
            return triangle_point(e0[:, :3], e1[:, :3], e0[:, 3], e1[:, 3])
    else:
        start = rng.normal(size=(count, 4, 3)) * 0.02
        start[:, 2:] += start[:, :2].mean(axis=1)[:, None] - start[:, 2:].mean(axis=1)[:, None] \
            + rng.normal(size=(count, 1, 3)) * 0.004  # across the first's middle
        name = "_moving_segments"

        def test(e0, e1):
            return segment_segment(*(e0[:, k] for k in range(4)), *(e1[:, k] for k in range(4)))
    end = start + rng.normal(size=(count, 4, 3)) * step
    tested = []
    moving = getattr(crossing, name)
    monkeypatch.setattr(crossing, name, lambda *a: tested.append(len(a[0])) or moving(*a))
    held = test(start, end)
    held_tested = sum(tested)
    tested.clear()
    fall = np.array([0.01, -0.02, -0.04])
    carried = test(start, end + fall)
    assert 0 < held_tested < 0.6 * count
    assert abs(sum(tested) - held_tested) <= 2  # (rounding at the bound)
    assert np.array_equal(carried.crossed, held.crossed) and held.crossed.sum() > 3
    assert np.allclose(carried.gap, held.gap, rtol=0.0, atol=1e-12)
    assert np.allclose(carried.normal, held.normal, rtol=0.0, atol=1e-9)


def test_a_point_falling_through_a_still_triangle_crosses_and_is_sent_back():
    tri = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    for end, crossed in ((-0.1, True), (0.05, False)):
        sep = triangle_point(tri, tri, np.array([[0.2, 0.2, 0.3]]), np.array([[0.2, 0.2, end]]))
        assert sep.crossed[0] == crossed
        # the normal points from the point to the triangle as they came: down
        assert np.allclose(sep.normal[0], (0.0, 0.0, -1.0))
        assert sep.gap[0] == pytest.approx(end)  # negative: behind the triangle
        assert np.allclose(sep.weight[0], (0.6, 0.2, 0.2))
    # beside the triangle: never crossed, separated along the nearest points
    sep = triangle_point(tri, tri, np.array([[2.0, 0.0, 0.3]]), np.array([[2.0, 0.0, -0.1]]))
    assert not sep.crossed[0] and sep.gap[0] == pytest.approx(np.hypot(1.0, 0.1))


def test_box_pairs_are_every_overlapping_pair():
    rng = np.random.default_rng(6)
    lo_a = rng.uniform(0, 10, (300, 3))
    hi_a = lo_a + rng.uniform(0, 1.5, (300, 3))
    lo_b = rng.uniform(0, 10, (200, 3))
    hi_b = lo_b + rng.uniform(0, 3.0, (200, 3))
    i, j = box_pairs(lo_a, hi_a, lo_b, hi_b)
    brute = np.all((lo_a[:, None] <= hi_b[None]) & (lo_b[None] <= hi_a[:, None]), axis=2)
    assert sorted(zip(i.tolist(), j.tolist())) == sorted(zip(*np.nonzero(brute)))


def test_creases_are_the_edges_out_of_flat_regions():
    box = box_mesh(1.0)
    edges, corners = box.creases
    assert len(edges) == 12 and len(corners) == 8  # no face diagonal
    segments = 12
    cylinder = cylinder_mesh(1.0, 1.0, segments)
    edges, corners = cylinder.creases
    # two rims and the sides; the caps' fanned spokes and centres lie in flat regions
    assert len(edges) == 3 * segments and len(corners) == 2 * segments
    x, _, tris, *_ = grid(4, 4)
    edges, corners = TriangleMesh(x, tris).creases
    assert len(edges) == 12 and len(corners) == 12  # a flat sheet: only its open border


def test_colouring_never_puts_a_moving_point_twice_in_a_group():
    rng = np.random.default_rng(7)
    points = 50
    moving = rng.random(points) < 0.8
    members = rng.integers(0, points, (1500, 3))
    groups = colour(members, moving)
    assert np.array_equal(np.sort(np.concatenate(groups)), np.arange(1500))
    for g in groups:
        used = np.concatenate([np.unique(row[moving[row]]) for row in members[g]])
        assert len(np.unique(used)) == len(used)


@pytest.mark.parametrize("k, points, count", [(2, 40, 300), (3, 50, 1500), (4, 300, 1000)])
def test_colouring_gives_each_constraint_the_lowest_group_free_at_its_turn(k, points, count):
    # the groups a greedy pass in index order makes, again and again on what is left (the
    # solvers' Gauss-Seidel order depends on them): checked against sets, one row at a time
    rng = np.random.default_rng(k)
    moving = rng.random(points) < 0.8
    members = rng.integers(0, points, (count, k))
    groups = colour(members, moving)
    group_of = np.empty(count, np.int64)
    for g, rows in enumerate(groups):
        group_of[rows] = g
        assert np.all(np.diff(rows) > 0)  # ascending within a group
    taken: list[set] = []  # per group, the moving items in it so far
    for c, row in enumerate(members):
        items = {int(i) for i in row if moving[i]}
        g = next((g for g, used in enumerate(taken) if not used & items), len(taken))
        if g == len(taken):
            taken.append(set())
        taken[g] |= items
        assert group_of[c] == g
    assert len(groups) == len(taken)


@pytest.mark.parametrize("case", ["dense", "touching", "large", "hashed"])
def test_box_pairs_across_two_sets_are_every_overlapping_pair(case):
    # Against all pairs tried: a dense set A (a cloth's neighbouring triangles overlap each
    # other) and a sparser B; boxes meeting only at a face (closed: they overlap); a few boxes
    # spanning many cells (the large-box pass); tiny boxes far apart (a hashed grid).
    from physanim.core.collision.crossing import box_pairs
    rng = np.random.default_rng(len(case))
    n, m, spread, size = {"dense": (8000, 600, 2.0, 0.05), "touching": (3000, 900, 1.0, 0.0),
                          "large": (3000, 400, 2.0, 0.05), "hashed": (3000, 900, 1e6, 0.01)}[case]
    ca, cb = rng.uniform(-spread, spread, (n, 3)), rng.uniform(-spread, spread, (m, 3))
    if case == "touching":  # unit cubes on a lattice: neighbours share faces
        ca, cb = rng.integers(0, 12, (n, 3)).astype(float), rng.integers(0, 12, (m, 3)) + 0.5
    ea = np.full((n, 3), 0.5) if case == "touching" else rng.uniform(0, size, (n, 3))
    eb = np.full((m, 3), 0.5) if case == "touching" else rng.uniform(0, size, (m, 3))
    if case == "large":
        eb[:5] = 1.5
    lo_a, hi_a, lo_b, hi_b = ca - ea, ca + ea, cb - eb, cb + eb
    i, j = box_pairs(lo_a, hi_a, lo_b, hi_b)
    every = np.all((lo_a[:, None] <= hi_b[None]) & (lo_b[None] <= hi_a[:, None]), axis=2)
    expected_i, expected_j = np.nonzero(every)
    assert len(expected_i) > 0 or case == "hashed"
    assert np.array_equal(i, expected_i) and np.array_equal(j, expected_j)


def test_box_pairs_refuse_more_candidates_than_allowed_before_making_them():
    """``max_candidates``: the grid's candidates (boxes sharing a cell, and the large boxes'
    pass against the whole other set) are counted before any is made."""
    from physanim.core.collision.broadphase import TooManyCandidates
    pile = np.zeros((400, 3))
    i, j = box_pairs(pile, pile + 0.1, pile, pile + 0.1, max_candidates=160_000)
    assert len(i) == 160_000  # all in one cell: every pair overlaps
    with pytest.raises(TooManyCandidates) as caught:
        box_pairs(pile, pile + 0.1, pile, pile + 0.1, max_candidates=159_999)
    assert (caught.value.candidates, caught.value.boxes) == (160_000, 800)
    # no shared cell: only the 3 large boxes of B, each tried against all 1,000 of A
    rng = np.random.default_rng(3)
    a, b = rng.uniform(0.0, 10.0, (1000, 3)), rng.uniform(100.0, 110.0, (100, 3))
    lo_b, hi_b = b.copy(), b + 0.01
    lo_b[:3], hi_b[:3] = -5.0, (15.0, 15.0, 15.0)
    i, j = box_pairs(a, a + 0.01, lo_b, hi_b, max_candidates=3000)
    assert len(i) == 3000 and set(j.tolist()) == {0, 1, 2}
    with pytest.raises(TooManyCandidates, match="3,000 candidate pairs"):
        box_pairs(a, a + 0.01, lo_b, hi_b, max_candidates=2999)


def _kept_matches_fresh(kept: KeptPairs, margin: float, lo, hi, split: int):
    """KeptPairs' pairs of the boxes lo, hi (within one set, or across its first ``split``
    boxes and the rest) equal a fresh search's, pairs and order; returns them."""
    from physanim.core.springs.self_collision import _pairs_within

    if kept.within:
        got, want = kept.pairs(margin, lo, hi), _pairs_within(lo, hi)
    else:
        got = kept.pairs(margin, lo[:split], hi[:split], lo[split:], hi[split:])
        want = box_pairs(lo[:split], hi[:split], lo[split:], hi[split:])
    if kept.exclude is not None:  # a fresh search's pairs without the excluded ones
        keep = ~kept.exclude(*want)
        assert 0 < keep.sum() < len(keep)
        want = want[0][keep], want[1][keep]
    assert len(want[0]) > 20
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
    return want


@pytest.mark.parametrize("within", [False, True])
def test_kept_pairs_equal_a_fresh_search_as_the_boxes_move(within):
    # KeptPairs gives exactly box_pairs's pairs (or, within one set, the grid's), in its
    # order, whether it reads the pairs kept from an earlier search (boxes moved less than the
    # margin) or searches again (moved further, or another count of boxes); pickled, it keeps
    # nothing.
    import pickle

    from physanim.core.springs.self_collision import _pairs_within

    rng = np.random.default_rng(11)
    centres = rng.uniform(0.0, 1.0, (600, 3))
    half = rng.uniform(0.005, 0.03, (600, 3))
    kept = KeptPairs(_pairs_within, within=True) if within else KeptPairs()
    margin, searches = 0.01, []

    def check(c):
        lo, hi = c - half[:len(c)], c + half[:len(c)]
        want = _kept_matches_fresh(kept, margin, lo, hi, 200)
        if within:  # only the pairs with a chosen box: the same as filtering afterwards
            only = rng.random(len(c)) < 0.2
            some = kept.pairs(margin, lo, hi, only=only)
            with_one = only[want[0]] | only[want[1]]
            assert 0 < with_one.sum() < len(want[0])
            np.testing.assert_array_equal(some[0], want[0][with_one])
            np.testing.assert_array_equal(some[1], want[1][with_one])
        searches.append(kept._grown)

    check(centres)
    for _ in range(5):  # each box within the margin of where it was searched
        check(centres + rng.uniform(-0.9 * margin, 0.9 * margin, centres.shape))
    assert all(g is searches[0] for g in searches)
    check(centres + (0.02, 0.0, 0.0))  # further: searched again
    assert searches[-1] is not searches[0]
    check(centres[:500])  # fewer boxes: searched again
    assert searches[-1] is not searches[-2]
    restored = pickle.loads(pickle.dumps(kept))
    assert restored._grown is None and restored._pairs is None and restored.within == within


def _every_third(i: np.ndarray, j: np.ndarray) -> np.ndarray:
    return (i + 2 * j) % 3 == 0


@pytest.mark.parametrize("within", [False, True])
@pytest.mark.parametrize("one_by_one", [True, False])
@pytest.mark.parametrize("exclude", [None, _every_third])
def test_kept_pairs_search_again_only_for_the_boxes_that_left_and_equal_a_fresh_search(
        within, one_by_one, exclude, monkeypatch):
    # A few boxes moving past their margin (some far across the set, some next to each
    # other, some of B's too) are searched again alone — tried against every box, or through
    # the search when they are not few — and merged into the kept pairs: the result is a fresh
    # search's, pairs and order, at every step of a random walk; many leaving at once search
    # everything again. With pairs excluded (as self-collision excludes elements that share
    # a vertex): a fresh search's without them, through every path; pickled, it keeps the rule.
    import pickle

    from physanim.core.collision import kept as kept_module
    from physanim.core.springs.self_collision import _pairs_within

    if not one_by_one:
        monkeypatch.setattr(kept_module, "FEW_TIMES_ALL", 0)

    rng = np.random.default_rng(12)
    n = 700
    c = rng.uniform(0.0, 1.0, (n, 3))
    half = rng.uniform(0.005, 0.03, (n, 3))
    kept = KeptPairs(_pairs_within, within=True, exclude=exclude) if within else \
        KeptPairs(exclude=exclude)
    margin = 0.01

    def check(c):
        _kept_matches_fresh(kept, margin, c - half, c + half, 300)

    check(c)
    assert kept.searches == [1, 0]
    for _ in range(30):
        c = c + rng.uniform(-0.002, 0.002, c.shape)  # all drift a little
        movers = rng.choice(n, 12, replace=False)
        c[movers] += rng.normal(0.0, 0.05, (12, 3))  # a few leave their grown boxes
        c[movers[:2]] = c[movers[2:4]] + 0.01  # and some land on each other
        check(c)
    whole, partial = kept.searches
    assert partial >= 25 and whole < 5
    c = c + rng.normal(0.0, 0.05, c.shape)
    check(c)  # most leave: everything searched again
    assert kept.searches[0] == whole + 1
    if within:  # a box gone NaN is refused by name, as a fresh search refuses it, and
        # nothing of that search is kept: the next boxes get a fresh search's pairs
        moved = c.copy()
        moved[:3] = moved[3:6] + 0.01
        moved[5] = np.nan
        with pytest.raises(PhysanimError, match="box 5 has a non-finite bound"):
            kept.pairs(margin, moved - half, moved + half)
        moved[5] = c[5]
        check(moved)
    kept = pickle.loads(pickle.dumps(kept))
    assert kept.exclude is exclude
    check(c)


@pytest.mark.parametrize("wide", [0, 1, 40])
def test_a_few_boxes_against_all_find_every_overlapping_pair_once(wide):
    """A partial search's few boxes against all (kept._few_with_all): through the slices of
    the boxes sorted by low x, and, where one very wide box makes the slices hold most pairs,
    trying every pair — each overlapping pair (closed boxes: touching counts) exactly once,
    as a brute-force test finds them; none for no boxes."""
    from physanim.core.collision.kept import _few_with_all

    rng = np.random.default_rng(wide)
    for trial in range(40):
        n, k = int(rng.integers(0, 500)), int(rng.integers(0, 50))
        c, half = rng.uniform(0.0, 1.0, (n, 3)), rng.uniform(0.0, 0.05, (n, 3))
        half[:min(wide, n), 0] = 2.0  # boxes across the whole set in x
        lo, hi = c - half, c + half
        cf, hf = rng.uniform(0.0, 1.0, (k, 3)), rng.uniform(0.0, 0.05, (k, 3))
        lo_f, hi_f = cf - hf, cf + hf
        if n and k:  # few boxes whose low x touches a box's high x exactly
            touch = rng.integers(0, n, k // 2)
            lo_f[:k // 2, 0] = hi[touch, 0]
        f, j = _few_with_all(lo_f, hi_f, lo, hi, None)
        found = list(zip(f.tolist(), j.tolist()))
        ff, jj = np.nonzero(np.all((lo_f[:, None] <= hi[None]) & (lo[None] <= hi_f[:, None]),
                                   axis=2))
        assert len(found) == len(set(found)), trial
        assert set(found) == set(zip(ff.tolist(), jj.tolist())), trial


def test_kept_pairs_pickled_before_they_moved_to_kept_load_and_search(monkeypatch):
    # a checkpoint written before KeptPairs moved to kept.py (and had partial searches) names
    # it in crossing.py, with none of the new attributes: it loads and searches as a new one
    import pickle

    from physanim.core.springs.self_collision import _pairs_within

    kept = KeptPairs(_pairs_within, within=True)
    monkeypatch.setattr(KeptPairs, "__getstate__", lambda self: {
        "find": self.find, "within": self.within, "_grown": None, "_pairs": None})
    data = pickle.dumps(kept, protocol=2)
    monkeypatch.undo()
    assert b"physanim.core.collision.kept" in data
    old = pickle.loads(data.replace(b"physanim.core.collision.kept",
                                    b"physanim.core.collision.crossing"))
    assert type(old) is KeptPairs and old.find is _pairs_within
    rng = np.random.default_rng(13)
    c, half = rng.uniform(0.0, 1.0, (500, 3)), rng.uniform(0.005, 0.03, (500, 3))
    _kept_matches_fresh(old, 0.01, c - half, c + half, 0)
    c[:5] += 0.1  # a few leave: a partial search
    _kept_matches_fresh(old, 0.01, c - half, c + half, 0)
    assert old.searches == [1, 1]


def test_kept_tests_equal_testing_every_pair_and_test_only_the_moved_ones():
    # A detection after a separating round (some end points moved, the starts the same) gives
    # the same separations as testing every pair, to the bit, and tests only the pairs with
    # a moved point; a kind the detection before did not test, or another start, is tested
    # afresh; pickled, it keeps nothing.
    import pickle

    rng = np.random.default_rng(5)
    n, tris = 300, rng.integers(0, 300, (400, 3))
    x0 = rng.uniform(0.0, 1.0, (n, 3))
    x1 = x0 + rng.normal(0.0, 0.05, (n, 3))
    i, j = np.nonzero(rng.random((len(tris), n)) < 0.02)  # pairs sorted by i, then j
    keys = i * n + j
    kept, tested = KeptTests(), []

    def detect(x0, x1, kind="faces", skip=False):
        moved, = kept.begin((x0, x1))
        tested.append(0)
        if skip:
            return None

        def test(rows):
            tested[-1] += len(rows)
            return triangle_point(x0[tris[i[rows]]], x1[tris[i[rows]]], x0[j[rows]], x1[j[rows]])

        got = kept.separations(kind, keys, moved[tris[i]].any(axis=1) | moved[j], test)
        want = triangle_point(x0[tris[i]], x1[tris[i]], x0[j], x1[j])
        for a, b in zip(got, want):
            np.testing.assert_array_equal(a, b)
        return got

    detect(x0, x1)
    assert tested[-1] == len(keys)
    for _ in range(3):  # rounds: a few end points pushed
        x1 = x1.copy()
        x1[rng.choice(n, 10, replace=False)] += rng.normal(0.0, 0.01, (10, 3))
        detect(x0, x1)
        assert 0 < tested[-1] < 0.5 * len(keys)
    detect(x0, x1)  # nothing moved: nothing tested
    assert tested[-1] == 0
    x1 = x1 + 0.01  # every point moved: every pair
    detect(x0, x1)
    assert tested[-1] == len(keys)
    x2 = x1.copy()
    x2[:150] += 0.02
    detect(x0, x2, skip=True)  # a detection that tests nothing of this kind, then one from
    detect(x0, x2)  # the same points: tested afresh (the kept tests are from older points)
    assert tested[-1] == len(keys)
    detect(x0, x2, kind="edges")  # another kind: its own
    assert tested[-1] == len(keys)
    detect(x0 + 0.01, x2 + 0.01)  # another start: every pair
    assert tested[-1] == len(keys)
    restored = pickle.loads(pickle.dumps(kept))
    assert restored._kept == {} and restored._inputs == ()
