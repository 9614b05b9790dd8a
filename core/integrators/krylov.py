"""Matrix-free Krylov solvers of the implicit steppers: each sees the matrix only as a product
``u -> A u``, so a stepper may build it from finite differences (:class:`~.implicit.ImplicitEuler`)
or assemble it sparse (the spring meshes' Baraff-Witkin stepper).

- :func:`bicgstab`: any nonsingular ``A`` (van der Vorst 1992); for implicit Euler on a general
  system, whose Jacobian is not symmetric.
- :func:`projected_pcg`: symmetric positive definite ``A`` with some directions prescribed
  (Baraff & Witkin's filtered conjugate gradients): preconditioned CG on the unknowns a
  projection leaves free.
- :func:`galerkin_start`: its first guess from the solutions of earlier systems of a sequence (the
  steps of a simulation): their combination closest to the new solution (Fischer 1998).
"""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..errors import SimulationError
from .base import non_finite

Product = Callable[[np.ndarray], np.ndarray]
MAX_CONDITION = 1e10  # of galerkin_start's k x k system: beyond, its coefficients are rounding


def bicgstab(
    matvec: Product, b: np.ndarray, rtol: float = 1e-8, max_iterations: int = 200,
) -> tuple[np.ndarray, int]:
    """Solve ``A x = b`` for a nonsymmetric ``A`` given only ``x -> A x`` (van der Vorst 1992).

    Args:
        matvec: product with ``A``, ``(n,) -> (n,)``.
        b: right-hand side, shape ``(n,)``.
        rtol: stop when ``|b - A x| <= rtol * |b|``.
        max_iterations: iteration cap (each iteration costs two ``matvec`` calls).

    Returns:
        ``(x, iterations)``. Raises SimulationError when ``b`` is non-finite, on breakdown, or
        without convergence within ``max_iterations``.
    """
    b_norm = float(np.linalg.norm(b))
    if not math.isfinite(b_norm):
        raise non_finite(b, "the linear system's right-hand side")
    x = np.zeros_like(b)
    if b_norm == 0.0:
        return x, 0
    goal = rtol * b_norm
    r, r_hat, p, v = b.copy(), b.copy(), np.zeros_like(b), np.zeros_like(b)
    rho = alpha = omega = 1.0
    for iteration in range(1, max_iterations + 1):
        rho_new = float(r_hat @ r)
        if not math.isfinite(rho_new) or rho_new == 0.0 or omega == 0.0:
            break  # breakdown: the Krylov recurrences would divide by zero
        p = r + (rho_new / rho) * (alpha / omega) * (p - omega * v)
        v = matvec(p)
        r_hat_v = float(r_hat @ v)
        if r_hat_v == 0.0:
            break
        alpha = rho_new / r_hat_v
        s = r - alpha * v
        if np.linalg.norm(s) <= goal:
            return x + alpha * p, iteration
        t = matvec(s)
        t_t = float(t @ t)
        if t_t == 0.0:
            break
        omega = float(t @ s) / t_t
        x = x + alpha * p + omega * s
        r = s - omega * t
        if np.linalg.norm(r) <= goal:
            return x, iteration
        rho = rho_new
    raise SimulationError(
        f"implicit solve failed after {iteration} of {max_iterations} iterations at relative "
        f"residual {np.linalg.norm(r) / b_norm:.3g} (target {rtol:g}) — use smaller substeps"
    )


def projected_pcg(
    matvec: Product, b: np.ndarray, precondition: Product, project: Product, rtol: float,
    max_iterations: int, start: np.ndarray | None = None, scale: float | None = None,
    start_product: np.ndarray | None = None,
) -> tuple[np.ndarray, int, float]:
    """Filtered preconditioned conjugate gradients (Baraff & Witkin 1998): solve ``A x = b`` on
    the directions ``project`` leaves free, for ``A`` symmetric positive definite there.

    Args:
        matvec: product with ``A``; any array shape (a spring mesh's is ``(n, 3)``).
        b: right-hand side, already projected. precondition: ``r -> approximately A^-1 r``.
        project: removes the prescribed directions from a fresh array, in place, and returns it.
        rtol: stop when ``|r| <= rtol * scale``; ``scale`` defaults to ``|b|``.
        max_iterations: iteration cap; at the cap the last iterate is returned (every CG
            iterate lowers the A-norm of the error, so a capped solve is still usable).
        start: first guess (projected here), or None for zero; a guess with a larger
            r . M^-1 r than zero's is not used.
        start_product: ``project(A start)`` when known (:func:`galerkin_start`'s), for a guess
            known to be no worse than zero in the A-norm: used as it is, without a product
            or the comparison with zero.

    Returns:
        ``(x, iterations, relative residual |r| / scale)``.

    Raises:
        SimulationError: ``A`` is not positive definite along a search direction, or a value
            became non-finite.
    """
    b_norm = float(np.sqrt(np.vdot(b, b))) if scale is None else scale
    if b_norm == 0.0:
        return np.zeros_like(b), 0, 0.0
    z = None
    if start is None:
        x, r = np.zeros_like(b), b.copy()
    elif start_product is not None:
        x, r = project(start), b - start_product
    else:
        x = project(start)
        r = b - project(matvec(x))
        z = project(precondition(r))
        zb = project(precondition(b))
        # a guess worse than none starts from zero instead — judged by r . M^-1 r, about the
        # error's A-norm, which CG lowers (by |r| alone a good extrapolation can look worse)
        if np.vdot(r, z) > np.vdot(b, zb):
            x, r, z, start = np.zeros_like(b), b.copy(), zb, None
    residual = float(np.sqrt(np.vdot(r, r))) / b_norm
    # a warm start gets at least one iteration (an accepted guess would err systematically
    # by up to the tolerance), unless it is exact already
    if residual <= rtol and (start is None or residual == 0.0):
        return x, 0, residual
    if z is None:
        z = project(precondition(r))
    p = z.copy()
    rz = float(np.vdot(r, z))
    if rz == 0.0:  # nothing the filter leaves free to correct
        return x, 0, residual
    for it in range(1, max_iterations + 1):
        q = project(matvec(p))
        pq = float(np.vdot(p, q))
        if not (pq > 0.0 and np.isfinite(pq)):
            raise SimulationError("the implicit solve lost positive definiteness "
                                  f"(p.Ap = {pq:.3g}) — lower the stiffness or add substeps")
        alpha = rz / pq
        x += alpha * p
        r -= alpha * q
        residual = float(np.sqrt(np.vdot(r, r))) / b_norm
        if residual <= rtol:
            return x, it, residual
        z = project(precondition(r))
        rz_new = float(np.vdot(r, z))
        p *= rz_new / rz
        p += z
        rz = rz_new
    return x, max_iterations, residual


def galerkin_start(matvec: Product, b: np.ndarray, project: Product,
                   candidates: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray | None]:
    """The combination of ``candidates`` (earlier solutions of systems like this one, newest
    first, each projected here) closest to the solution of ``A x = b`` in the A-norm — the
    Galerkin projection onto their span (Fischer 1998, for sequences of right-hand sides):
    solves (U^T A U) c = U^T b for the k coefficients c, k products with ``A``. Contains the
    newest candidate alone and every extrapolation of them, so it is never a worse start in the
    A-norm than any of those. Where the candidates are nearly dependent (a motion changing
    little from step to step: the k x k system singular, indefinite or conditioned beyond
    MAX_CONDITION, its coefficients rounding) it is the newest extrapolated along the one
    before, 2 u0 - u1 (the newest alone when there is one).

    Args: matvec, project: as :func:`projected_pcg`'s. b: the right-hand side (projected).
    candidates: newest first, each of b's shape (not changed).

    Returns ``(guess, project(A guess))``; the product (from the candidates' own, no further
    product with ``A``) only for the Galerkin combination, which is never a worse start than
    zero in the A-norm either (its error's squared A-norm is zero's less c^T U^T A U c), so
    :func:`projected_pcg` may take it as it is (``start_product``); None for the fallback."""
    u = [project(np.array(c, dtype=np.float64)) for c in candidates]
    fallback = 2.0 * u[0] - u[1] if len(u) > 1 else u[0]
    au = [project(matvec(c)) for c in u]
    gram = np.array([[float(np.vdot(a, c)) for c in u] for a in au])
    rhs = np.array([float(np.vdot(c, b)) for c in u])
    gram = 0.5 * (gram + gram.T)  # (symmetric up to rounding)
    try:
        np.linalg.cholesky(gram)  # positive definite: the candidates independent
        if np.linalg.cond(gram) > MAX_CONDITION:
            return fallback, None
        coefficient = np.linalg.solve(gram, rhs)
    except np.linalg.LinAlgError:
        return fallback, None
    if not np.all(np.isfinite(coefficient)):
        return fallback, None
    out, product = coefficient[0] * u[0], coefficient[0] * au[0]
    for k, c, a in zip(coefficient[1:], u[1:], au[1:]):
        out += k * c
        product += k * a
    return out, product
