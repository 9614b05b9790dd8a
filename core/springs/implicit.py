"""Implicit (backward) Euler for spring meshes, Baraff & Witkin's "Large steps in cloth
simulation" (1998): one linearised step solved by preconditioned conjugate gradients on the
spring Jacobians, with pinned vertices handled by filtering (their velocity change is given).

    (M - h df/dv - h^2 df/dx) dv = h (f0 + h df/dx v0),   v1 = v0 + dv,   x1 = x0 + h v1

The matrix is symmetric (spring Jacobians with the compressed-spring term clamped are
symmetric negative semi-definite), so CG applies, with a Jacobi preconditioner from the
per-vertex mass and incident spring constants and a warm start from the previous step's dv.
As in Baraff & Witkin, the solve is inexact: CG stops at the tolerance or the iteration cap.
Every CG iterate lowers the A-norm of the error, so a capped solve is still a damped, stable
step; only a loss of positive definiteness or a non-finite value is an error.
"""
from __future__ import annotations

import numpy as np

from ..errors import SimulationError
from ..integrators import StepReport


class BaraffWitkin:
    """Implicit Euler stepper with the entry point of every integrator: ``step(system, t, h)``.

    The system must offer ``mass`` (n,), ``free`` (n,) bool, ``pinned_velocity(t)`` (n, 3),
    ``weight_norm()`` (|M g| [N], the force scale residuals are judged against),
    ``forces_at(t, x, v) -> (n, 3)``, ``linearize(t, x, v)`` -> Jacobian blocks whose
    ``operator(cx, cv)`` adds (cx df/dx + cv df/dv) u into ``out``, ``diagonal(h) -> (n,)`` (a positive estimate of the
    matrix diagonal), and ``x``/``v`` attributes it updates.

    Args:
        tolerance: relative residual at which CG stops. max_iterations: CG cap.
    """

    name = "IMPLICIT"

    TOLERANCE = 1e-3  # relative residual: Baraff & Witkin's inexact solve, visually converged

    def __init__(self, tolerance: float = TOLERANCE, max_iterations: int = 200):
        self.tolerance = float(tolerance)
        self.max_iterations = int(max_iterations)
        self._warm: np.ndarray | None = None  # last dv: the next step's first guess
        self.last_residual = 0.0
        self.last_iterations = 0

    def step(self, system, t: float, h: float) -> StepReport:
        x0, v0 = system.x, system.v
        mass = system.mass[:, None]
        free = system.free[:, None]
        f0 = system.forces_at(t, x0, v0)
        blocks = system.linearize(t, x0, v0)  # Jacobian blocks once; many products below
        a_ops = [b.operator(h * h, h) for b in blocks]  # h^2 df/dx + h df/dv, pre-combined
        rhs = f0.copy()
        for b in blocks:
            b.operator(h, 0.0)(v0, rhs)  # f0 + h df/dx v0
        rhs *= h

        def apply_a(u: np.ndarray) -> np.ndarray:
            out = np.zeros_like(u)
            for op in a_ops:
                op(u, out)
            return mass * u - out

        # pinned vertices: their velocity change is prescribed; move it to the right-hand side
        given = np.where(free, 0.0, system.pinned_velocity(t + h) - v0)
        b = np.where(free, rhs - (apply_a(given) if np.any(given) else 0.0), 0.0)
        inv_diag = np.where(free, 1.0 / system.diagonal(h)[:, None], 0.0)
        start = self._warm if self._warm is not None and self._warm.shape == b.shape else None
        # residuals are judged against the larger of the right-hand side and the impulse gravity
        # gives in one step: near equilibrium b -> 0 and a purely relative test never stops
        scale = max(float(np.sqrt(np.sum(b * b))), h * float(system.weight_norm()))
        dv, iterations, residual = self._pcg(apply_a, b, inv_diag, free, start, scale)
        self._warm = dv.copy()
        self.last_residual, self.last_iterations = residual, iterations
        dv = dv + given
        v1 = v0 + dv
        x1 = x0 + h * v1
        if not (np.all(np.isfinite(x1)) and np.all(np.isfinite(v1))):
            raise SimulationError("state became non-finite in the implicit step")
        system.x, system.v = x1, v1
        return StepReport(steps=1, evaluations=iterations, h_last=h)

    def _pcg(self, apply_a, b, inv_diag, free, start=None, scale=None):
        """Filtered preconditioned conjugate gradients (only free vertices move). Stops when
        |r| <= tolerance * scale (default |b|)."""
        b_norm = float(np.sqrt(np.sum(b * b))) if scale is None else scale
        if b_norm == 0.0:
            return np.zeros_like(b), 0, 0.0
        if start is None:
            x = np.zeros_like(b)
            r = b.copy()
        else:
            x = np.where(free, start, 0.0)
            r = b - np.where(free, apply_a(x), 0.0)
        residual = float(np.sqrt(np.sum(r * r))) / b_norm
        if residual <= self.tolerance:
            return x, 0, residual
        z = inv_diag * r
        p = z.copy()
        rz = float(np.sum(r * z))
        for it in range(1, self.max_iterations + 1):
            q = np.where(free, apply_a(p), 0.0)
            pq = float(np.sum(p * q))
            if not (pq > 0.0 and np.isfinite(pq)):
                raise SimulationError("the implicit solve lost positive definiteness "
                                      f"(p.Ap = {pq:.3g}) — lower the stiffness or add substeps")
            alpha = rz / pq
            x += alpha * p
            r -= alpha * q
            residual = float(np.sqrt(np.sum(r * r))) / b_norm
            if residual <= self.tolerance:
                return x, it, residual
            z = inv_diag * r
            rz_new = float(np.sum(r * z))
            p = z + (rz_new / rz) * p
            rz = rz_new
        return x, self.max_iterations, residual
