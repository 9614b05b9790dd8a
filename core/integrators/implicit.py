"""Linearised implicit Euler for stiff systems (its BiCGSTAB solve is in :mod:`.krylov`)."""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from .base import Integrator, JacobianSystem, StepReport, is_a, non_finite
from .krylov import bicgstab


class ImplicitEuler(Integrator):
    """Linearly implicit (Rosenbrock) Euler for stiff systems: one Newton step of backward Euler.

    Solves ``(I - h J) dy = h f(t, y)`` with ``J = df/dy`` at ``(t, y)`` and sets ``y += dy``:
    first order, stable for any ``h`` on damped and oscillating linear systems (it damps them).
    ``J u`` is matrix-free, ``(f(t, y + eps u) - f(t, y)) / eps`` with
    ``eps = sqrt(machine eps) * (1 + |y|) / |u|``, unless the system is a
    :class:`~.base.JacobianSystem` (its ``jacobian_vector(t, y, u)`` is then used instead and
    not counted in ``StepReport.evaluations``). Linear systems are solved by
    :func:`~.krylov.bicgstab`.

    With ``second_order`` (``y = [x, v]``, ``f = [v, a]``) the same solution is found from the
    velocity system of Baraff & Witkin, "Large steps in cloth simulation" (1998):
    ``(I - h da/dv - h^2 da/dx) dv = h (a + h da/dx v)``, ``dx = h (v + dv)``. It has half the
    unknowns and, unlike the full system, stays well conditioned when positions [m] and
    velocities [m/s] differ by the stiff frequency: there, finite differences along Krylov
    vectors mixing both scales lose the stiff part and BiCGSTAB fails.

    Args:
        rtol: relative residual tolerance of the linear solve.
        max_iterations: BiCGSTAB iteration cap.
        second_order: use the velocity system (needs the ``[x, v]`` convention and even ``dim``).
    """

    name = "IMPLICIT"
    stages = 4  # BiCGSTAB's residual and search vectors
    FD_SCALE = math.sqrt(np.finfo(np.float64).eps)  # balances truncation against rounding

    def __init__(self, rtol: float = 1e-8, max_iterations: int = 200, second_order: bool = False):
        if not (math.isfinite(rtol) and rtol > 0.0):
            raise ValueError(f"rtol must be finite and > 0 (got {rtol!r})")
        self.rtol, self.max_iterations = float(rtol), int(max_iterations)
        self.second_order = bool(second_order)

    def _step_impl(self, system, t, y, dt):
        report = StepReport(steps=1, evaluations=1, h_last=dt)
        f0 = system.derivative(t, y)
        if not np.all(np.isfinite(f0)):
            raise non_finite(f0, "the derivative")
        jv = self._jacobian_product(system, t, y, f0, report)

        def solve(matvec, b):
            return bicgstab(matvec, b, rtol=self.rtol, max_iterations=self.max_iterations)[0]

        if not self.second_order:
            return y + solve(lambda u: u - dt * jv(u), dt * f0), report
        n = y.shape[0] // 2
        if y.shape[0] != 2 * n:
            raise ValueError(f"second-order implicit Euler needs even dim (got {y.shape[0]})")
        v, zero = y[n:], np.zeros(n)
        rhs = dt * (f0[n:] + dt * jv(np.concatenate([v, zero]))[n:])
        dv = solve(lambda w: w - jv(np.concatenate([dt * dt * w, dt * w]))[n:], rhs)
        return y + np.concatenate([dt * (v + dv), dv]), report

    def _jacobian_product(self, system, t: float, y: np.ndarray, f0: np.ndarray,
                          report: StepReport) -> Callable[[np.ndarray], np.ndarray]:
        """``u -> J u`` at ``(t, y)``: the system's own product, or a forward difference of
        ``derivative`` from ``f0`` (each counted in ``report.evaluations``)."""
        if is_a(system, JacobianSystem):
            return lambda u: np.asarray(system.jacobian_vector(t, y, u), dtype=np.float64)
        y_scale = 1.0 + float(np.linalg.norm(y))

        def jv(u: np.ndarray) -> np.ndarray:
            u_norm = float(np.linalg.norm(u))
            if u_norm == 0.0:
                return np.zeros_like(u)
            eps = self.FD_SCALE * y_scale / u_norm
            report.evaluations += 1
            return (system.derivative(t, y + eps * u) - f0) / eps

        return jv
