"""The implicit solves' first guess from earlier solutions (:func:`galerkin_start`) against what it
promises: the A-norm-closest combination of its candidates on the free directions."""
from __future__ import annotations

import numpy as np

from physanim.core.integrators.krylov import galerkin_start, projected_pcg


def _system(seed: int = 0, n: int = 30):
    """A symmetric positive definite A (n, 3) -> (n, 3), the filter that prescribes every
    fifth row (zeroes it), and a projected right-hand side."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(3 * n, 3 * n))
    a = q.T @ q / (3 * n) + np.eye(3 * n)
    free = np.ones((n, 1))
    free[::5] = 0.0

    def project(u):
        u *= free
        return u

    def matvec(u):
        return (a @ u.ravel()).reshape(u.shape)

    b = project(rng.normal(size=(n, 3)))
    return matvec, project, b, rng


def _a_error(matvec, project, b, x):
    """The A-norm of the error of x on the free directions, up to a constant:
    x.Ax - 2 x.b = |x - x*|_A^2 - |x*|_A^2 (x* the filtered system's solution)."""
    x = project(x.copy())
    return float(np.vdot(x, project(matvec(x))) - 2.0 * np.vdot(x, b))


def test_galerkin_start_is_no_worse_than_any_candidate_or_their_extrapolation():
    matvec, project, b, rng = _system()
    exact = projected_pcg(matvec, b, lambda r: r.copy(), project, 1e-13, 500)[0]
    candidates = [exact + 0.1 * k * rng.normal(size=exact.shape) for k in (1, 2, 3)]
    start = galerkin_start(matvec, b, project, candidates)[0]
    best = _a_error(matvec, project, b, start)
    others = [*candidates, 2.0 * candidates[0] - candidates[1],
              1.5 * candidates[0] - 0.5 * candidates[1]]
    assert all(best <= _a_error(matvec, project, b, c) + 1e-12 for c in others)
    assert np.all(start[::5] == 0.0)  # on the free directions only
    assert all(not np.all(c[::5] == 0.0) for c in candidates)  # (the candidates untouched)


def test_galerkin_start_finds_a_solution_in_the_candidates_span_exactly():
    matvec, project, b, rng = _system(1)
    exact = projected_pcg(matvec, b, lambda r: r.copy(), project, 1e-14, 500)[0]
    other = project(rng.normal(size=exact.shape))
    # x* = 0.3 c0 + 0.7 c1 with c1 = (x* - 0.3 c0) / 0.7
    candidates = [other, (exact - 0.3 * other) / 0.7]
    np.testing.assert_allclose(galerkin_start(matvec, b, project, candidates)[0], exact, atol=1e-9)


def test_dependent_candidates_give_the_newest_extrapolated():
    """Candidates along one direction (a motion changing little from step to step: the
    oscillator's one axis): the k x k system is singular, and the start is the newest
    extrapolated along the one before."""
    matvec, project, b, rng = _system(2)
    c = project(rng.normal(size=b.shape))
    for others in ([0.5 * c], [0.5 * c, 0.25 * c], [(1.0 - 1e-13) * c]):
        expected = 2.0 * c - others[0]
        np.testing.assert_allclose(galerkin_start(matvec, b, project, [c, *others])[0], expected,
                                   rtol=1e-12)
        # (no product to hand on: CG judges the extrapolation against zero itself)
        assert galerkin_start(matvec, b, project, [c, *others])[1] is None


def test_galerkin_start_hands_on_its_product_and_cg_solves_from_it_as_from_the_guess():
    """The product galerkin_start returns is project(A guess), made from the candidates'
    own products; CG started with it reaches the solution as CG started from the guess
    alone (which computes that product itself)."""
    matvec, project, b, rng = _system(3)
    exact = projected_pcg(matvec, b, lambda r: r.copy(), project, 1e-13, 500)[0]
    candidates = [exact + 0.05 * k * rng.normal(size=exact.shape) for k in (1, 2, 3)]
    guess, product = galerkin_start(matvec, b, project, candidates)
    np.testing.assert_allclose(product, project(matvec(guess)), rtol=1e-12, atol=1e-12)
    plain = projected_pcg(matvec, b, lambda r: r.copy(), project, 1e-10, 500, guess.copy())
    handed = projected_pcg(matvec, b, lambda r: r.copy(), project, 1e-10, 500, guess.copy(),
                           None, product)
    np.testing.assert_allclose(handed[0], exact, atol=1e-8)
    np.testing.assert_allclose(handed[0], plain[0], atol=1e-8)
    assert handed[1] <= plain[1] + 1
