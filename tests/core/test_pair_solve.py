"""Pairs of weighted point sums kept apart (core/contact/pair_solve.py): the velocity response's
passes over a crowded heap."""
import numpy as np

from physanim.core.contact import pair_solve
from physanim.core.contact.pair_solve import PointPairs, respond

REST_SPEED = 0.4  # [m/s] (a spring mesh's at 2 sub-steps of a 24 fps frame)


def _heap(seed: int, side: int = 8):
    """A layer falling onto another: each point of the upper grid paired with the triangles
    of the lower one under it (its barycentric weights, clamped, and -1 for the point), and a
    knot of points over one lower point, which is in more pairs than CROWD (so relaxed
    Jacobi passes)."""
    rng = np.random.default_rng(seed)
    g = np.arange(side) * 0.1
    lower = np.stack(np.meshgrid(g, g, [0.0], indexing="ij"), -1).reshape(-1, 3)
    upper = lower[:, :2] + 0.05 + rng.normal(0.0, 0.01, (len(lower), 2))
    centre = lower[len(lower) // 2 + side // 2, :2]
    crowd = centre + rng.normal(0.0, 0.01, (pair_solve.CROWD, 2))  # a knot on one point
    upper = np.column_stack([np.concatenate([upper, crowd]), np.full(len(upper) + len(crowd),
                                                                     0.005)])
    k = np.arange(side * side).reshape(side, side)
    quads = np.stack([k[:-1, :-1], k[1:, :-1], k[1:, 1:], k[:-1, 1:]], -1).reshape(-1, 4)
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    vertex, weight = [], []
    for p, point in enumerate(upper):
        for t in tris:
            a, b, c = lower[t]
            lo, hi = np.minimum(np.minimum(a, b), c) - 0.03, np.maximum(np.maximum(a, b), c) + 0.03
            if np.all(point[:2] >= lo[:2]) and np.all(point[:2] <= hi[:2]):
                m = np.array([[b[0] - a[0], c[0] - a[0]], [b[1] - a[1], c[1] - a[1]]])
                u, w = np.clip(np.linalg.solve(m, point[:2] - a[:2]), 0.0, 1.0)
                u, w = (u, w) if u + w <= 1.0 else (u / (u + w), w / (u + w))
                vertex.append([*t, len(lower) + p])
                weight.append([1.0 - u - w, u, w, -1.0])
    vertex, weight = np.array(vertex), np.array(weight)
    normal = np.tile([0.0, 0.0, -1.0], (len(vertex), 1))
    pairs = PointPairs(vertex, weight, normal, np.zeros_like(normal), np.zeros(len(vertex)), 0.01)
    assert np.bincount(vertex.ravel()).max() > pair_solve.CROWD
    v = np.zeros((len(lower) + len(upper), 3))
    v[len(lower):] = rng.normal(0.0, 0.05, (len(upper), 3)) + (0.0, 0.0, -0.6)
    return pairs, v, rng.uniform(0.5, 2.0, len(v))


def _approach(pairs: PointPairs, v: np.ndarray) -> np.ndarray:
    rel = np.einsum("ck,ckj->cj", pairs.weight, v[pairs.vertex])
    return -np.einsum("ij,ij->i", rel, pairs.normal)


def test_a_crowded_heaps_normal_passes_end_once_no_pair_approaches_faster_than_the_tolerance(
        monkeypatch):
    # relaxed Jacobi passes take a part off the largest approach left per pass: they end once
    # every pair approaches slower than the tolerance (of the rest speed), not after all
    # RELAXED_PASSES (which a tolerance of nothing takes); momentum is kept exactly
    applied = []
    apply = pair_solve._apply
    monkeypatch.setattr(pair_solve, "_apply", lambda *a: applied.append(1) or apply(*a))
    for seed in range(3):
        passes = []
        for tolerance in (1e-2, pair_solve.APPROACH_TOLERANCE, 0.0):
            monkeypatch.setattr(pair_solve, "APPROACH_TOLERANCE", tolerance)
            pairs, v, mass = _heap(seed)
            momentum = (mass[:, None] * v).sum(axis=0)
            assert _approach(pairs, v).max() > 0.4  # [m/s]
            applied.clear()
            respond(pairs, v, 1.0 / mass, pairs.normal, np.zeros_like(pairs.normal), 0.0, 0.0,
                    REST_SPEED, coloured=False)
            passes.append(len(applied))
            if passes[-1] < pair_solve.RELAXED_PASSES:
                assert _approach(pairs, v).max() <= tolerance * REST_SPEED
            np.testing.assert_allclose((mass[:, None] * v).sum(axis=0), momentum, atol=1e-12)
        assert passes[0] <= passes[1] <= passes[2] == pair_solve.RELAXED_PASSES
        assert passes[0] < pair_solve.RELAXED_PASSES
