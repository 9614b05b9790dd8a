"""Broad phases: every one returns exactly the pairs a brute-force test finds (closed
intervals), on more than 10,000 random scenes (fixed seeds), on degenerate input, and — for
sweep and prune — from one frame to the next with temporal coherence.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from physanim.core.collision import broadphase as bp
from physanim.core.collision.broadphase_base import iter_ranges
from physanim.core.errors import PhysanimError

ROOT = Path(__file__).resolve().parents[2]

# name -> factory of a fresh instance; parameters chosen to reach every code path (coherent and
# fresh sorts, every sweep axis count, tiny/huge/automatic cells, the large-box pass, octrees from
# a single cell to the deepest level)
METHODS = {
    "sap1": lambda: bp.SweepAndPrune(1),
    "sap2": lambda: bp.SweepAndPrune(2),
    "sap3": lambda: bp.SweepAndPrune(3),
    "sap1-fresh": lambda: bp.SweepAndPrune(1, coherence=False),
    "sap3-fresh-counted": lambda: bp.SweepAndPrune(3, coherence=False, count_swaps=True),
    "grid-auto": lambda: bp.UniformGrid(),
    "grid-0.3": lambda: bp.UniformGrid(0.3),
    "grid-1": lambda: bp.UniformGrid(1.0),
    "grid-4": lambda: bp.UniformGrid(4.0),
    "grid-0.25-large": lambda: bp.UniformGrid(0.25, max_cells_per_box=2),
    "octree": lambda: bp.Octree(),
    "octree-root-only": lambda: bp.Octree(max_depth=0),
    "octree-3-1": lambda: bp.Octree(max_depth=3, leaf_size=1),
    "octree-deepest": lambda: bp.Octree(max_depth=bp.MAX_OCTREE_DEPTH, leaf_size=1),
    "octree-6-4": lambda: bp.Octree(max_depth=6, leaf_size=4),
}


def brute_pairs(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Reference: the closed-interval test on every ordered pair, no shortcuts."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    hit = np.all((lo[:, None, :] <= hi[None, :, :]) & (lo[None, :, :] <= hi[:, None, :]), axis=2)
    i, j = np.nonzero(np.triu(hit, k=1))
    return np.stack([i, j], axis=1).astype(np.int64).reshape(-1, 2)


# --- random scenes ---------------------------------------------------------------------------

def random_scene(rng: np.random.Generator, n: int, kind: int) -> tuple[np.ndarray, np.ndarray]:
    """n boxes inside about [-1, 6]^3, of one of eight kinds chosen to provoke edge cases."""
    if kind == 0:  # continuous positions and sizes
        lo = rng.uniform(0, 5, (n, 3))
        hi = lo + rng.uniform(0, 1.5, (n, 3))
    elif kind == 1:  # integer lattice: touching faces, identical and zero-size boxes
        lo = rng.integers(0, 5, (n, 3)).astype(float)
        hi = lo + rng.integers(0, 3, (n, 3))
    elif kind == 2:  # points on a coarse lattice: coincident points
        lo = rng.integers(0, 3, (n, 3)).astype(float)
        hi = lo.copy()
    elif kind == 3:  # a few prototypes copied many times
        proto_lo = rng.uniform(0, 3, (3, 3))
        proto_hi = proto_lo + rng.uniform(0, 1, (3, 3))
        pick = rng.integers(0, 3, n)
        lo, hi = proto_lo[pick], proto_hi[pick]
    elif kind == 4:  # wildly mixed sizes: huge boxes among tiny ones
        lo = rng.uniform(0, 5, (n, 3))
        size = np.where(rng.random((n, 1)) < 0.2, rng.uniform(2, 6, (n, 1)), 1e-6)
        hi = lo + size * rng.uniform(0.5, 1, (n, 3))
    elif kind == 5:  # dyadic coordinates: exactly on cell and octree boundaries
        lo = rng.integers(0, 40, (n, 3)) / 8.0
        hi = lo + rng.integers(0, 8, (n, 3)) / 8.0
    elif kind == 6:  # flat: every box in the plane z = 1
        lo = np.c_[rng.uniform(0, 5, (n, 2)), np.ones(n)]
        hi = lo + np.c_[rng.uniform(0, 1, (n, 2)), np.zeros(n)]
    else:  # around the origin with signed zeros
        lo = rng.integers(-2, 2, (n, 3)).astype(float)
        hi = lo + rng.integers(0, 2, (n, 3))
        lo[lo == 0] = -0.0
    return lo, hi


def batched_scenes(seed: int, scenes: int, max_n: int):
    """Many small scenes in one call, each far from the others: returns the boxes and the
    reference pairs (brute force per scene, shifted to the batch's indices)."""
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.cbrt(scenes)))
    los, his, refs, start = [], [], [], 0
    for s in range(scenes):
        n = int(rng.integers(0, max_n + 1))
        lo, hi = random_scene(rng, n, s % 8)
        offset = 20.0 * np.array([s % side, (s // side) % side, s // side**2])
        los.append(lo + offset)
        his.append(hi + offset)
        refs.append(brute_pairs(lo, hi) + start)
        start += n
    return np.concatenate(los), np.concatenate(his), np.concatenate(refs)


BATCH_SEEDS = range(12)
SCENES_PER_BATCH = 900
SINGLE_SEEDS = range(4)
SINGLE_SCENES = 160
BIG_SCENES = [(100, 3000, 0), (101, 2000, 1), (102, 2000, 4), (103, 1500, 5), (104, 2000, 3)]


def test_at_least_ten_thousand_random_cases():
    total = (len(BATCH_SEEDS) * SCENES_PER_BATCH + len(SINGLE_SEEDS) * SINGLE_SCENES
             + len(BIG_SCENES))
    assert total >= 10_000


@pytest.mark.parametrize("seed", BATCH_SEEDS)
def test_batched_small_scenes_match_brute_force(seed):
    lo, hi, reference = batched_scenes(seed, SCENES_PER_BATCH, max_n=14)
    reference = reference[np.lexsort((reference[:, 1], reference[:, 0]))]
    assert np.array_equal(bp.AllPairs().pairs(lo, hi), reference)
    for name, make in METHODS.items():
        got = make().pairs(lo, hi)
        assert np.array_equal(got, reference), name


@pytest.mark.parametrize("seed", SINGLE_SEEDS)
def test_single_small_scenes_match_brute_force(seed):
    """Scenes on their own: the octree's root and the grid's origin fit each scene."""
    rng = np.random.default_rng(1000 + seed)
    methods = {name: make() for name, make in METHODS.items()}  # reused: SAP resets on new n
    for s in range(SINGLE_SCENES):
        lo, hi = random_scene(rng, int(rng.integers(0, 25)), s % 8)
        reference = brute_pairs(lo, hi)
        assert np.array_equal(bp.AllPairs().pairs(lo, hi), reference)
        for name, method in methods.items():
            assert np.array_equal(method.pairs(lo, hi), reference), (name, s)


@pytest.mark.parametrize("seed,n,kind", BIG_SCENES)
def test_big_scenes_match_all_pairs(seed, n, kind):
    rng = np.random.default_rng(seed)
    lo, hi = random_scene(rng, n, kind)
    lo, hi = lo * 4, lo * 4 + (hi - lo)  # spread out: a few neighbours per box
    reference = bp.AllPairs().pairs(lo, hi)
    assert len(reference) > 0
    for name, make in METHODS.items():
        method = make()
        assert np.array_equal(method.pairs(lo, hi), reference), name
        assert method.last_stats.pair_count == len(reference)
        assert method.last_stats.candidate_count >= len(reference)


def test_all_pairs_matches_brute_force_across_row_blocks(monkeypatch):
    """AllPairs compares blocks of rows; blocks of a few rows must not lose a pair."""
    rng = np.random.default_rng(7)
    lo, hi = random_scene(rng, 300, 1)
    monkeypatch.setattr(bp, "PAIR_CHUNK", 1000)  # 3 rows per block
    assert np.array_equal(bp.AllPairs().pairs(lo, hi), brute_pairs(lo, hi))


def test_small_batches_of_candidates_give_the_same_pairs(monkeypatch):
    """Candidate enumeration in batches (iter_ranges) loses nothing at batch borders."""
    rng = np.random.default_rng(8)
    lo, hi = random_scene(rng, 400, 0)
    reference = brute_pairs(lo, hi)
    monkeypatch.setattr(iter_ranges, "__defaults__", (97,))
    for name, make in METHODS.items():
        assert np.array_equal(make().pairs(lo, hi), reference), name


def test_iter_ranges_lists_every_source_offset_once():
    count = np.array([0, 3, 0, 0, 5, 1, 0, 200, 2, 0])
    expected = [(s, k) for s, c in enumerate(count) for k in range(c)]
    for chunk in (1, 2, 7, 64, 1000):
        got = [(int(s), int(k)) for src, off in iter_ranges(count, chunk)
               for s, k in zip(src, off)]
        assert got == expected, chunk


# --- output form and degenerate input --------------------------------------------------------

@pytest.fixture(params=["all-pairs", *METHODS])
def method(request):
    return bp.AllPairs() if request.param == "all-pairs" else METHODS[request.param]()


def test_output_is_canonical(method):
    rng = np.random.default_rng(3)
    lo, hi = random_scene(rng, 200, 1)
    pairs = method.pairs(lo, hi)
    assert pairs.dtype == np.int64 and pairs.ndim == 2 and pairs.shape[1] == 2
    assert np.all(pairs[:, 0] < pairs[:, 1])
    keys = pairs[:, 0] * 200 + pairs[:, 1]
    assert np.all(np.diff(keys) > 0)  # sorted lexicographically and unique


@pytest.mark.parametrize("n", [0, 1])
def test_no_pairs_for_fewer_than_two_boxes(method, n):
    pairs = method.pairs(np.zeros((n, 3)), np.ones((n, 3)))
    assert pairs.shape == (0, 2) and pairs.dtype == np.int64
    assert method.last_stats.box_count == n and method.last_stats.pair_count == 0


def test_touching_boxes_overlap(method):
    """Closed intervals: a shared face, edge or corner is an overlap; a one-ulp gap is not."""
    unit = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [1, 1, 1], [0, 0, 1]])
    lo = np.concatenate([unit, [[np.nextafter(1.0, 2.0), 0, 0]]])  # last: just past the first
    hi = lo + 1
    pairs = method.pairs(lo, hi)
    assert [0, 1] in pairs.tolist() and [0, 2] in pairs.tolist() and [0, 3] in pairs.tolist()
    assert [0, 5] not in pairs.tolist()
    assert np.array_equal(pairs, brute_pairs(lo, hi))


def test_zero_size_boxes(method):
    """Points overlap when they coincide or lie on (or in) a box; otherwise not."""
    lo = np.array([[0.0, 0, 0], [0, 0, 0], [1, 0.5, 0.5], [2, 2, 2], [0.5, 0.5, 0.5],
                   [np.nextafter(1.0, 2.0), 0.5, 0.5]])
    hi = lo.copy()
    hi[4] = [1, 1, 1]  # box 4 spans [0.5, 1]^3: holds point 2 on its face, not point 5
    assert np.array_equal(method.pairs(lo, hi), np.array([[0, 1], [2, 4]]))


def test_identical_boxes_all_overlap(method):
    lo = np.tile([[1.0, 2.0, 3.0]], (12, 1))
    pairs = method.pairs(lo, lo + 0.5)
    assert len(pairs) == 12 * 11 // 2
    assert np.array_equal(pairs, brute_pairs(lo, lo + 0.5))


def test_signed_zero_touching(method):
    lo = np.array([[-1.0, -1, -1], [0.0, 0.0, 0.0]])
    hi = np.array([[-0.0, -0.0, -0.0], [1.0, 1, 1]])
    assert method.pairs(lo, hi).tolist() == [[0, 1]]


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_bound_names_box_and_value(method, bad):
    lo = np.zeros((5, 3))
    hi = np.ones((5, 3))
    hi[3, 1] = bad
    with pytest.raises(ValueError, match=r"box 3 has a non-finite bound: .*" + repr(bad)) as err:
        method.pairs(lo, hi)
    assert isinstance(err.value, PhysanimError)
    lo[2, 0] = np.nan
    with pytest.raises(ValueError, match=r"box 2 .*lo = \(nan, 0.0, 0.0\)"):
        method.pairs(lo, hi)


def test_inverted_box_names_box_axis_and_values(method):
    lo = np.zeros((4, 3))
    hi = np.ones((4, 3))
    lo[2, 2] = 1.5
    with pytest.raises(ValueError, match=r"box 2 is inverted along z: lo = 1.5 > hi = 1.0"):
        method.pairs(lo, hi)


@pytest.mark.parametrize("lo_shape,hi_shape", [((4, 2), (4, 2)), ((4, 3), (5, 3)), ((3,), (3,))])
def test_bad_shapes(method, lo_shape, hi_shape):
    with pytest.raises(ValueError, match="shape"):
        method.pairs(np.zeros(lo_shape), np.ones(hi_shape))


def test_extreme_coordinates(method):
    """Far from the origin and at very different scales the pairs stay exact."""
    rng = np.random.default_rng(11)
    lo, hi = random_scene(rng, 120, 1)
    for scale, shift in ((1e-9, 0.0), (1.0, 1e12), (1e6, -3e15)):
        a, b = lo * scale + shift, hi * scale + shift
        assert np.array_equal(method.pairs(a, b), brute_pairs(a, b)), (scale, shift)


def test_overflowing_span_is_refused():
    lo = np.array([[-1e308, 0, 0], [1e308, 0, 0]])
    with pytest.raises(ValueError, match="float64 range"):
        bp.Octree().pairs(lo, lo + 1)


@pytest.mark.parametrize("make,message", [
    (lambda: bp.SweepAndPrune(axes=0), "axes must be 1, 2 or 3"),
    (lambda: bp.SweepAndPrune(axes=4), "axes must be 1, 2 or 3"),
    (lambda: bp.UniformGrid(cell_size=0.0), r"cell_size must be finite and > 0 \(got 0.0\)"),
    (lambda: bp.UniformGrid(cell_size=float("nan")), "cell_size must be finite"),
    (lambda: bp.UniformGrid(max_cells_per_box=0), "max_cells_per_box"),
    (lambda: bp.Octree(max_depth=20), r"max_depth must be an integer in 0..19 \(got 20\)"),
    (lambda: bp.Octree(max_depth=-1), "max_depth"),
    (lambda: bp.Octree(leaf_size=0), r"leaf_size must be an integer >= 1 \(got 0\)"),
])
def test_bad_parameters_are_refused(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_grid_too_fine_names_cell_size():
    lo = np.array([[0.0, 0, 0], [10, 0, 0]])
    with pytest.raises(ValueError, match=r"cell_size 1e-09 m is too small .* along x"):
        bp.UniformGrid(1e-9).pairs(lo, lo + 0.5)


def test_grid_hashes_cells_of_a_huge_grid():
    """2**62 or more cells cannot be numbered: keys are hashed, the pairs stay exact."""
    rng = np.random.default_rng(12)
    lo = rng.integers(0, 4, (300, 3)) * 1e-6 + rng.uniform(0, 5, (300, 3)).round(0)
    hi = lo + rng.integers(0, 2, (300, 3)) * 1e-6
    grid = bp.UniformGrid(1e-6)
    assert np.array_equal(grid.pairs(lo, hi), brute_pairs(lo, hi))
    assert grid.last_stats.hashed


def test_grid_large_boxes_take_the_all_pairs_pass():
    rng = np.random.default_rng(13)
    lo, hi = random_scene(rng, 300, 4)
    grid = bp.UniformGrid(0.5, max_cells_per_box=8)
    assert np.array_equal(grid.pairs(lo, hi), brute_pairs(lo, hi))
    assert grid.last_stats.large_box_count > 0


def test_grid_refuses_more_candidates_than_allowed_before_testing_any():
    """``max_candidates``: a call that would test more candidate pairs (cells and the large
    boxes' pass, counted as the stats count them) raises before testing; at the limit it runs."""
    rng = np.random.default_rng(15)
    lo, hi = random_scene(rng, 300, 4)
    free = bp.UniformGrid(0.5, max_cells_per_box=8)
    expected = free.pairs(lo, hi)
    count = free.last_stats.candidate_count
    assert free.last_stats.large_box_count > 0
    assert np.array_equal(bp.UniformGrid(0.5, 8, max_candidates=count).pairs(lo, hi), expected)
    with pytest.raises(bp.TooManyCandidates) as caught:
        bp.UniformGrid(0.5, 8, max_candidates=count - 1).pairs(lo, hi)
    assert (caught.value.candidates, caught.value.boxes, caught.value.limit) == (
        count, 300, count - 1)
    # boxes piled on one spot: n (n - 1) / 2 candidates, refused without making them
    pile = np.zeros((200_000, 3))
    with pytest.raises(bp.TooManyCandidates, match="19,999,900,000 candidate pairs among "
                                                   "200,000 boxes"):
        bp.UniformGrid(1.0, max_candidates=10**6).pairs(pile, pile + 0.1)


# --- stats -----------------------------------------------------------------------------------

def test_stats_count_candidates():
    rng = np.random.default_rng(14)
    lo, hi = random_scene(rng, 500, 0)
    lo, hi = lo * 3, hi * 3
    everything = bp.AllPairs()
    everything.pairs(lo, hi)
    assert everything.last_stats.candidate_count == 500 * 499 // 2
    for name, make in METHODS.items():
        method = make()
        method.pairs(lo, hi)
        stats = method.last_stats
        assert stats.pair_count <= stats.candidate_count <= 500 * 499 // 2, name
    sap1, sap3 = bp.SweepAndPrune(1), bp.SweepAndPrune(3)
    sap1.pairs(lo, hi)
    sap3.pairs(lo, hi)
    assert sap3.last_stats.candidate_count <= sap1.last_stats.candidate_count
    assert sap1.last_stats.sweep_axis == 0
    octree = bp.Octree(max_depth=6, leaf_size=4)
    octree.pairs(lo, hi)
    assert octree.last_stats.entry_count <= 8 * 500 and 0 < octree.last_stats.depth <= 6


def test_sweep_picks_the_axis_with_fewest_overlaps():
    """Boxes strung along x overlap a lot on y and z: the 3-axis sweep enumerates along x."""
    rng = np.random.default_rng(15)
    lo = np.c_[rng.uniform(0, 1000, 400), rng.uniform(0, 1, (400, 2))]
    hi = lo + 1
    sap = bp.SweepAndPrune(3)
    assert np.array_equal(sap.pairs(lo, hi), brute_pairs(lo, hi))
    assert sap.last_stats.sweep_axis == 0
    sap = bp.SweepAndPrune(3)
    sap.pairs(lo[:, [1, 2, 0]], hi[:, [1, 2, 0]])
    assert sap.last_stats.sweep_axis == 2


# --- sweep and prune: temporal coherence ------------------------------------------------------

def random_walk(seed: int, n: int, frames: int, step: float):
    rng = np.random.default_rng(seed)
    centre = rng.uniform(0, 10, (n, 3))
    half = rng.uniform(0.2, 0.6, (n, 3))
    for _ in range(frames):
        yield centre - half, centre + half
        centre = centre + rng.normal(0, step, (n, 3))


@pytest.mark.parametrize("axes", [1, 2, 3])
def test_coherent_sweep_matches_a_fresh_one_with_fewer_swaps(axes):
    coherent = bp.SweepAndPrune(axes, coherence=True, count_swaps=True)
    fresh = bp.SweepAndPrune(axes, coherence=False, count_swaps=True)
    for frame, (lo, hi) in enumerate(random_walk(20 + axes, 400, 30, 0.02)):
        got = coherent.pairs(lo, hi)
        assert np.array_equal(got, fresh.pairs(lo, hi))
        assert np.array_equal(got, bp.AllPairs().pairs(lo, hi))
        c, f = coherent.last_stats, fresh.last_stats
        assert c.fresh_sort == (frame == 0) and f.fresh_sort
        assert c.candidate_count == f.candidate_count
        if frame:
            assert 0 < c.swap_count < f.swap_count / 20, frame
            assert c.displacement < f.displacement
        for stats in (c, f):  # Diaconis-Graham: swaps <= displacement <= 2 swaps
            assert stats.swap_count <= stats.displacement <= 2 * stats.swap_count


def test_coherent_sweep_with_boxes_at_rest_makes_no_swaps():
    lo, hi = next(random_walk(30, 300, 1, 0.0))
    sap = bp.SweepAndPrune(3, count_swaps=True)
    first = sap.pairs(lo, hi)
    again = sap.pairs(lo, hi)
    assert np.array_equal(first, again)
    assert sap.last_stats.swap_count == 0 and sap.last_stats.displacement == 0
    assert not sap.last_stats.fresh_sort


def test_coherent_sweep_with_big_jumps_still_exact():
    """Coherence is only an optimisation: teleporting boxes give the exact pairs."""
    rng = np.random.default_rng(31)
    sap = bp.SweepAndPrune(2)
    for frame in range(10):
        lo, hi = random_scene(rng, 250, frame % 8)
        assert np.array_equal(sap.pairs(lo, hi), brute_pairs(lo, hi))


def test_changed_box_count_resets_coherence():
    sap = bp.SweepAndPrune(1, count_swaps=True)
    frames = list(random_walk(32, 200, 3, 0.05))
    sap.pairs(*frames[0])
    assert sap.last_stats.fresh_sort
    lo, hi = frames[1]
    assert np.array_equal(sap.pairs(lo[:150], hi[:150]), brute_pairs(lo[:150], hi[:150]))
    assert sap.last_stats.fresh_sort
    assert np.array_equal(sap.pairs(lo[:150], hi[:150]), brute_pairs(lo[:150], hi[:150]))
    assert not sap.last_stats.fresh_sort
    sap.reset()
    assert np.array_equal(sap.pairs(*frames[2]), brute_pairs(*frames[2]))
    assert sap.last_stats.fresh_sort


def test_swap_count_is_off_unless_asked():
    sap = bp.SweepAndPrune(1)
    for lo, hi in random_walk(33, 100, 2, 0.05):
        sap.pairs(lo, hi)
    assert sap.last_stats.swap_count is None and sap.last_stats.displacement > 0


@pytest.mark.parametrize("m", [0, 1, 2, 3, 17, 64, 257, 1000])
def test_count_inversions_matches_brute_force(m):
    rng = np.random.default_rng(m)
    for perm in (rng.permutation(m), np.argsort(np.arange(m) + rng.normal(0, 3, m)),
                 np.arange(m), np.arange(m)[::-1].copy()):
        brute = int(np.triu(perm[:, None] > perm[None, :], k=1).sum())
        assert bp.count_inversions(perm) == brute


# --- box policies ----------------------------------------------------------------------------

def random_rotations(rng, n):
    q = rng.normal(size=(n, 4))
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], axis=1)


def test_box_policies_fixed_cubes_hold_every_orientation_and_aabbs_are_tight():
    rng = np.random.default_rng(40)
    n = 200
    centres = rng.uniform(0, 8, (n, 3))
    half = rng.uniform(0.1, 0.8, (n, 3))
    radius = np.linalg.norm(half, axis=1)  # bounding sphere of the box
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    cube_lo, cube_hi = bp.cube_boxes(centres, radius)
    for _ in range(5):
        rot = random_rotations(rng, n)
        points = centres[:, None, :] + np.einsum("nab,nkb->nka", rot, corners * half[:, None, :])
        owner = np.repeat(np.arange(n), 8)
        aabb_lo, aabb_hi = bp.aabb_of_points(points.reshape(-1, 3), owner, n)
        assert np.allclose(aabb_lo, points.min(axis=1)) and np.allclose(aabb_hi, points.max(axis=1))
        obb_lo, obb_hi = bp.aabb_of_oriented_boxes(centres, rot, half)
        assert np.allclose(obb_lo, aabb_lo) and np.allclose(obb_hi, aabb_hi)
        assert np.all(cube_lo <= aabb_lo + 1e-12) and np.all(aabb_hi <= cube_hi + 1e-12)
        tight = bp.SweepAndPrune(1).pairs(aabb_lo, aabb_hi)
        loose = bp.SweepAndPrune(1).pairs(cube_lo, cube_hi)
        tight_set, loose_set = set(map(tuple, tight)), set(map(tuple, loose))
        assert tight_set <= loose_set and len(loose_set) > len(tight_set)


def test_box_policy_helpers_refuse_bad_input():
    with pytest.raises(ValueError, match=r"object 1 must be finite and >= 0 \(got -1.0\)"):
        bp.cube_boxes(np.zeros((3, 3)), [0.5, -1.0, 0.5])
    with pytest.raises(ValueError, match="object 2 owns no points"):
        bp.aabb_of_points(np.zeros((4, 3)), np.array([0, 1, 1, 3]), 4)
    with pytest.raises(ValueError, match="owners must lie in 0..1"):
        bp.aabb_of_points(np.zeros((2, 3)), np.array([0, 2]), 2)
    with pytest.raises(ValueError, match="rotations"):
        bp.aabb_of_oriented_boxes(np.zeros((2, 3)), np.zeros((3, 3, 3)), np.ones((2, 3)))
    lo, hi = bp.aabb_of_points(np.zeros((0, 3)), np.zeros(0, dtype=int), 0)
    assert lo.shape == hi.shape == (0, 3)
