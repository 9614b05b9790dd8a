"""Exact triangle-triangle overlap against an independent brute-force reference.

The reference decides "do two closed triangles meet?" as "does one of the six edges meet the
other triangle?" (true for any two triangles, degenerate ones included: an extreme point of the
intersection always lies on an edge of one of them), with segment-triangle and segment-segment
tests written from scratch in exact Python-integer arithmetic. Cases have integer (or dyadic,
scaled to integer) coordinates so the reference is exact; many are touching, coplanar or
degenerate by construction, and random unimodular integer maps (which preserve incidence exactly)
move them off the coordinate planes.
"""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.collision.predicates import orient2d, orient3d
from physanim.core.collision.tritri import hulls_overlap_2d, triangles_overlap


# --- reference (object arrays of Python ints, vectorised over cases) --------------------------

def _obj(x):
    return np.asarray(x).astype(np.int64).astype(object)


def _cross(u, v):
    return np.stack([u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1], u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2],
                     u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]], axis=1)


def _dot(u, v):
    return u[:, 0] * v[:, 0] + u[:, 1] * v[:, 1] + u[:, 2] * v[:, 2]


def _b(x):
    return np.asarray(x).astype(bool)


def _zero(v):
    return _b(v[:, 0] == 0) & _b(v[:, 1] == 0) & _b(v[:, 2] == 0)


def ref_segment_segment(p, q, r, s):
    """Closed 3D segments pq, rs (possibly points) meet."""
    d1, d2, w = q - p, s - r, r - p
    m = _cross(d1, d2)
    mm = _dot(m, m)
    coplanar = _b(_dot(w, m) == 0)
    tn, un = _dot(_cross(w, d2), m), _dot(_cross(w, d1), m)
    general = coplanar & _b(mm != 0) & _b(tn >= 0) & _b(tn <= mm) & _b(un >= 0) & _b(un <= mm)
    z1, z2 = _zero(d1), _zero(d2)
    both_points = z1 & z2 & _zero(w)

    def point_on(x, a, d):
        e = x - a
        t = _dot(e, d)
        return _zero(_cross(e, d)) & _b(t >= 0) & _b(t <= _dot(d, d))

    p_on_rs = z1 & ~z2 & point_on(p, r, d2)
    r_on_pq = z2 & ~z1 & point_on(r, p, d1)
    parallel = ~z1 & ~z2 & _b(mm == 0)
    collinear = parallel & _zero(_cross(w, d1))
    tr, ts, tq = _dot(r - p, d1), _dot(s - p, d1), _dot(d1, d1)
    lo = np.where(_b(tr < ts), tr, ts)
    hi = np.where(_b(tr < ts), ts, tr)
    overlap_1d = collinear & _b(lo <= tq) & _b(hi >= 0)
    return general | both_points | p_on_rs | r_on_pq | overlap_1d


def ref_segment_triangle(p, q, a, b, c):
    """Closed segment pq (possibly a point) meets closed triangle abc (possibly degenerate)."""
    n = _cross(b - a, c - a)
    flat = _zero(n)
    dp, dq = _dot(n, p - a), _dot(n, q - a)
    same_side = _b(dp * dq > 0)
    coplanar = _b(dp == 0) & _b(dq == 0)
    verts, edges = (a, b, c), (b - a, c - b, a - c)

    def inside(x, scale):  # x / scale inside the triangle (n oriented with abc)
        ok = np.ones(len(x), dtype=bool)
        for v, e in zip(verts, edges):
            ok &= _b(_dot(n, _cross(e, x - scale[:, None] * v)) * scale >= 0)
        return ok

    one = _obj(np.ones(len(p)))
    edge_hit = (ref_segment_segment(p, q, a, b) | ref_segment_segment(p, q, b, c)
                | ref_segment_segment(p, q, c, a))
    planar = inside(p, one) | inside(q, one) | edge_hit
    d = dp - dq
    d_safe = np.where(_b(d == 0), one, d)
    crossing = inside(dp[:, None] * q - dq[:, None] * p, d_safe)
    proper = np.where(same_side, False, np.where(coplanar, planar, crossing))
    return np.where(flat, edge_hit, proper)


def ref_triangles_overlap(t1, t2):
    """Some edge of one triangle meets the other (integer-valued (n, 3, 3) inputs)."""
    t1, t2 = _obj(t1), _obj(t2)
    hit = np.zeros(len(t1), dtype=bool)
    for s, t in ((t1, t2), (t2, t1)):
        for i in range(3):
            hit |= _b(ref_segment_triangle(s[:, i], s[:, (i + 1) % 3], t[:, 0], t[:, 1], t[:, 2]))
    return hit


# --- case generators ---------------------------------------------------------------------------

def _unimodular(rng, n):
    """(n, 3, 3) random integer matrices with determinant +-1 (products of elementary shears)."""
    m = np.tile(np.eye(3, dtype=np.int64), (n, 1, 1))
    for _ in range(3):
        i = rng.integers(0, 3, n)
        j = (i + rng.integers(1, 3, n)) % 3
        e = np.tile(np.eye(3, dtype=np.int64), (n, 1, 1))
        e[np.arange(n), i, j] = rng.integers(-2, 3, n)
        m = np.einsum("nij,njk->nik", m, e)
    perm = np.array([rng.permutation(3) for _ in range(n)])
    return m[np.arange(n)[:, None], perm]


def _move(rng, t1, t2):
    """Apply the same random unimodular map + integer shift to both triangles of each case."""
    n = len(t1)
    m = _unimodular(rng, n)
    shift = rng.integers(-50, 51, (n, 1, 3))

    def f(t):
        return np.einsum("nij,nkj->nki", m, t) + shift

    return f(t1).astype(np.float64), f(t2).astype(np.float64)


def _touching_cases(rng, n):
    """Triangle pairs built to touch or nearly touch: shared vertices, a vertex on an edge or a
    face of the other triangle, an edge crossing an edge, coplanar pairs, and the same shifted
    by one unit (a near miss) — all integer, then moved by a unimodular map."""
    s = 6  # barycentric weights sum to s, so points on t1 are integer after scaling t1 by s
    t1 = rng.integers(-5, 6, (n, 3, 3)) * s
    w = rng.integers(0, s + 1, (n, 3))
    w[:, 2] = 0
    w[:, 1] = np.minimum(w[:, 1], s - w[:, 0])
    w[:, 2] = s - w[:, 0] - w[:, 1]
    kind = rng.integers(0, 6, n)
    w[kind == 1, 2] = 0  # kind 1: a point on an edge of t1
    w[kind == 1, 1] = s - w[kind == 1, 0]
    x = np.einsum("nk,nkj->nj", w, t1) // s  # a point of t1 (exact: t1 is a multiple of s)
    t2 = rng.integers(-5, 6, (n, 3, 3)) * s
    t2[:, 0] = x                                       # kinds 0, 1: a vertex on t1
    shared = kind == 2
    t2[shared, 0] = t1[shared, rng.integers(0, 3)]     # a shared vertex
    edge = kind == 3                                   # t2's edge passes through x
    t2[edge, 1] = 2 * x[edge] - t2[edge, 0]
    flat = kind == 4                                   # coplanar pairs in z = const
    t1[flat, :, 2] = 7
    t2[flat, :, 2] = 7
    t2[flat, 0] = x[flat]
    t2[flat, 0, 2] = 7
    miss = rng.random(n) < 0.3                         # nudge one unit: a near miss or not
    t2[miss] += rng.integers(-1, 2, (int(miss.sum()), 1, 3))
    return t1, t2


def _check(t1, t2):
    got = triangles_overlap(t1, t2)
    want = ref_triangles_overlap(t1, t2)
    bad = np.nonzero(got != want)[0]
    assert len(bad) == 0, (f"{len(bad)} of {len(t1)} disagree, e.g. case {bad[0]}: "
                           f"{t1[bad[0]].tolist()} vs {t2[bad[0]].tolist()} "
                           f"got {got[bad[0]]} want {want[bad[0]]}")
    return got


# --- tests -------------------------------------------------------------------------------------

@pytest.mark.parametrize("span", [2, 4, 12])
def test_random_integer_triangles_match_reference(span):
    # tiny integer boxes make coplanar, collinear, touching and degenerate cases common
    rng = np.random.default_rng(span)
    n = 12_000
    t1 = rng.integers(0, span + 1, (n, 3, 3)).astype(np.float64)
    t2 = rng.integers(0, span + 1, (n, 3, 3)).astype(np.float64)
    got = _check(t1, t2)
    assert 0.1 * n < got.sum() < 0.95 * n


def test_constructed_touching_cases_match_reference():
    rng = np.random.default_rng(7)
    t1, t2 = _touching_cases(rng, 12_000)
    t1, t2 = _move(rng, t1, t2)
    got = _check(t1, t2)
    assert got.sum() > 4000 and (~got).sum() > 1000
    # the constructed set really is full of boundary cases
    sides = np.stack([orient3d(t2[:, 0], t2[:, 1], t2[:, 2], t1[:, i]) for i in range(3)], 1)
    assert (sides == 0).any(axis=1).sum() > 3000


def test_coplanar_integer_triangles_match_reference():
    rng = np.random.default_rng(11)
    n = 12_000
    t1 = rng.integers(-4, 5, (n, 3, 3))
    t2 = rng.integers(-4, 5, (n, 3, 3))
    t1[:, :, 2] = 0
    t2[:, :, 2] = 0
    t1, t2 = _move(rng, t1, t2)
    got = _check(t1, t2)
    assert 0.2 * n < got.sum() < 0.9 * n


def test_random_dyadic_triangles_match_reference():
    # generic positions with 10 fractional bits: exact in binary, integer after scaling by 1024
    rng = np.random.default_rng(3)
    n = 12_000
    t1 = rng.integers(-1024, 1025, (n, 3, 3))
    t2 = t1.mean(axis=1, keepdims=True).astype(np.int64) + rng.integers(-900, 901, (n, 3, 3))
    got = triangles_overlap(t1 / 1024.0, t2 / 1024.0)
    want = ref_triangles_overlap(t1, t2)
    np.testing.assert_array_equal(got, want)
    assert 0.1 * n < got.sum() < 0.9 * n


def test_scaled_and_translated_cases_keep_their_answer():
    # exact predicates: scaling by powers of two and large translations by multiples of a power
    # of two that keep coordinates exact do not change any answer
    rng = np.random.default_rng(5)
    t1, t2 = _touching_cases(rng, 3000)
    base = triangles_overlap(t1.astype(float), t2.astype(float))
    for scale, shift in ((2.0 ** -30, 0.0), (2.0 ** 20, 0.0), (1.0, 2.0 ** 30)):
        got = triangles_overlap(t1 * scale + shift, t2 * scale + shift)
        np.testing.assert_array_equal(got, base)


def test_symmetric_and_vertex_order_invariant():
    rng = np.random.default_rng(9)
    t1 = rng.integers(0, 4, (5000, 3, 3)).astype(float)
    t2 = rng.integers(0, 4, (5000, 3, 3)).astype(float)
    base = triangles_overlap(t1, t2)
    np.testing.assert_array_equal(triangles_overlap(t2, t1), base)
    np.testing.assert_array_equal(triangles_overlap(t1[:, [2, 0, 1]], t2[:, [1, 0, 2]]), base)


def test_hand_made_cases():
    t = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    cases = [
        ([[0, 0, 0], [0, 0, 1], [1, 1, 1]], True),            # shared vertex
        ([[0.5, 0, 0], [0.5, 0, 1], [0.5, 1, 1]], True),      # vertex on an edge
        ([[0.25, 0.25, 0], [1, 1, 1], [0, 1, 1]], True),      # vertex on the face
        ([[0.25, 0.25, 1e-300], [1, 1, 1], [0, 1, 1]], False),  # a hair above the face
        ([[1, 1, 0], [2, 1, 0], [1, 2, 0]], False),           # coplanar, apart
        ([[0.5, 0.5, 0], [2, 1, 0], [1, 2, 0]], True),        # coplanar, touching at a point
        ([[0, 0, 1], [1, 0, 1], [0, 1, 1]], False),           # parallel planes
        ([[0.2, 0.2, -1], [0.2, 0.2, 1], [0.2, 0.2, 2]], True),  # degenerate: a segment through
        ([[3, 3, -1], [3, 3, 1], [3, 3, 2]], False),          # degenerate, beside it
        ([[0.1, 0.1, 0], [0.1, 0.1, 0], [0.1, 0.1, 0]], True),  # a point on the face
        ([[0.1, 0.1, 0.1], [0.1, 0.1, 0.1], [0.1, 0.1, 0.1]], False),
    ]
    t2 = np.array([c for c, _ in cases], dtype=float)
    want = np.array([w for _, w in cases])
    np.testing.assert_array_equal(triangles_overlap(np.repeat(t[None], len(t2), 0), t2), want)


def test_hulls_overlap_2d_degenerate_sets():
    seg = np.array([[[0, 0], [2, 0], [1, 0]]], dtype=float)
    for other, want in (([[1, 0], [1, 0], [1, 0]], True), ([[3, 0], [3, 0], [3, 0]], False),
                        ([[1, -1], [1, 1], [1, 1]], True), ([[2, 0], [3, 0], [4, 0]], True),
                        ([[2.5, 0], [3, 0], [4, 0]], False)):
        assert hulls_overlap_2d(seg, np.array([other], dtype=float))[0] == want


def test_rejects_non_finite_and_bad_shapes():
    t = np.zeros((2, 3, 3))
    bad = t.copy()
    bad[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match="pair 1 has a non-finite vertex"):
        triangles_overlap(t, bad)
    with pytest.raises(ValueError, match=r"\(n, 3, 3\)"):
        triangles_overlap(t, t[:, :2])
    assert triangles_overlap(np.zeros((0, 3, 3)), np.zeros((0, 3, 3))).shape == (0,)


# --- predicates --------------------------------------------------------------------------------

def _fraction_sign3(rows):
    from fractions import Fraction
    out = []
    for r in rows:
        a, b, c, d = ([Fraction(float(x)) for x in r[i:i + 3]] for i in (0, 3, 6, 9))
        u = [b[i] - a[i] for i in range(3)]
        v = [c[i] - a[i] for i in range(3)]
        w = [d[i] - a[i] for i in range(3)]
        det = (u[0] * (v[1] * w[2] - v[2] * w[1]) + u[1] * (v[2] * w[0] - v[0] * w[2])
               + u[2] * (v[0] * w[1] - v[1] * w[0]))
        out.append((det > 0) - (det < 0))
    return np.array(out)


def test_orient3d_exact_on_nearly_coplanar_points():
    rng = np.random.default_rng(2)
    n = 1500
    a, b, c = (rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-3, 4, (n, 1)) for _ in range(3))
    st = rng.uniform(-1, 2, (n, 2))
    d = a + st[:, :1] * (b - a) + st[:, 1:] * (c - a)  # coplanar up to rounding
    # a third exactly coplanar: small even integers, scaled far below a large offset
    k = n // 3
    ia, ib, ic = (2 * rng.integers(-500, 500, (k, 3)) for _ in range(3))
    ia, ib, ic, idd = (3.0 + x * 2.0 ** -40 for x in (ia, ib, ic, (ia + ib) // 2 + ic - ia))
    a[:k], b[:k], c[:k], d[:k] = ia, ib, ic, idd
    got = orient3d(a, b, c, d)
    want = _fraction_sign3(np.concatenate([a, b, c, d], axis=1))
    np.testing.assert_array_equal(got, want)
    assert (got == 0).sum() >= k


def test_orient2d_exact_and_antisymmetric():
    rng = np.random.default_rng(4)
    a, b = rng.normal(size=(3000, 2)), rng.normal(size=(3000, 2))
    c = a + rng.uniform(-1, 2, (3000, 1)) * (b - a)
    s = orient2d(a, b, c)
    np.testing.assert_array_equal(orient2d(b, a, c), -s)
    np.testing.assert_array_equal(orient2d(b, c, a), s)
    ints = rng.integers(-3, 4, (3000, 3, 2)).astype(float)
    s = orient2d(ints[:, 0], ints[:, 1], ints[:, 2])
    u, v = ints[:, 1] - ints[:, 0], ints[:, 2] - ints[:, 0]
    np.testing.assert_array_equal(s, np.sign(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]))
