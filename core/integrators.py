"""Time integrators that advance a flat state ``y`` of any system by one time step.

An integrator sees only the solver interface of Witkin & Baraff's notes (:class:`System`):
``dim``, ``get_state()``, ``set_state(y)`` and ``derivative(t, y)``. The state is one flat
float64 vector. Second-order systems use the convention ``y = [x, v]`` — the first ``dim / 2``
values are positions, the last ``dim / 2`` velocities — and ``derivative`` returns ``[v, a]``;
:class:`SymplecticEuler` and ``ImplicitEuler(second_order=True)`` (what ``make_integrator``
builds for ``IMPLICIT``) rely on it; every other integrator works on any first-order system.

Euler, midpoint, RK4 and the Dormand–Prince 5(4) pair are Butcher tableaux run by one generic
:func:`rk_step` (as in ``scipy.integrate._ivp.rk``). :class:`Integrator.step` does the bookkeeping
(read state, check the result is finite, write state) and subclasses implement ``_step_impl``.
No integrator holds module-level state; :class:`AdaptiveRK` remembers its last good step size on
the instance only.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol
from collections.abc import Callable

import numpy as np

from .errors import SimulationError

Derivative = Callable[[float, np.ndarray], np.ndarray]


class System(Protocol):
    """What an integrator needs (Witkin & Baraff): ``dim``; ``get_state() -> (dim,)`` float64;
    ``set_state(y)``; ``derivative(t, y) -> (dim,)``, a pure function of ``t`` [s] and ``y``."""

    dim: int

    def get_state(self) -> np.ndarray: ...

    def set_state(self, y: np.ndarray) -> None: ...

    def derivative(self, t: float, y: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True, eq=False)
class Tableau:
    """Butcher tableau of an explicit Runge–Kutta method, optionally with an embedded pair.

    Attributes:
        A: stage coefficients, shape ``(s, s)``, strictly lower triangular (explicit method).
        B: weights of the solution, shape ``(s,)``; they sum to 1.
        C: stage times as fractions of the step, shape ``(s,)``; ``C[i] == sum(A[i])``.
        order: order of the solution given by ``B``.
        E: error-estimate weights ``B - B_hat`` of the embedded solution (order ``order - 1``),
            shape ``(s,)``, or None for a method without error estimate.
        name: short identifier, e.g. ``"RK4"``.

    The arrays are copied and made read-only. Raises ValueError naming the bad field.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    order: int
    E: np.ndarray | None = None
    name: str = ""

    def __post_init__(self) -> None:
        for field in ("A", "B", "C", "E"):
            if getattr(self, field) is not None:
                array = np.array(getattr(self, field), dtype=np.float64)
                array.flags.writeable = False
                object.__setattr__(self, field, array)
        A, B, C, E = self.A, self.B, self.C, self.E
        s = B.shape[0] if B.ndim == 1 else 0
        E_shape = (s,) if E is None else E.shape
        if s == 0 or A.shape != (s, s) or C.shape != (s,) or E_shape != (s,):
            self._fail(f"need A (s, s) and B, C, E (s,) (got {A.shape}, {B.shape}, {C.shape}, "
                       f"{E_shape})")
        # Consistency conditions catch a mistyped coefficient before it silently costs accuracy.
        for failed, message in (
            (not isinstance(self.order, int) or self.order < 1, f"order {self.order!r} not >= 1"),
            (not all(np.isfinite(a).all() for a in (A, B, C, E) if a is not None), "non-finite"),
            (np.any(np.triu(A) != 0.0), "A must be strictly lower triangular (explicit method)"),
            (abs(B.sum() - 1.0) > 1e-12, f"B must sum to 1 (got {B.sum()!r})"),
            (np.any(np.abs(A.sum(axis=1) - C) > 1e-12), f"C must be the row sums of A (got {C})"),
            (E is not None and abs(E.sum()) > 1e-12, "E must sum to 0"),
        ):
            if failed:
                self._fail(message)

    def _fail(self, message: str) -> None:
        raise ValueError(f"tableau {self.name!r}: {message}")

    @property
    def stages(self) -> int:
        """Number of stages ``s`` (derivative evaluations per step without reuse)."""
        return self.B.shape[0]

    @property
    def fsal(self) -> bool:
        """First-same-as-last: the last stage is ``f(t + h, y_new)`` and can start the next step."""
        return bool(self.C[-1] == 1.0 and self.B[-1] == 0.0 and np.array_equal(self.A[-1], self.B))


EULER_TABLEAU = Tableau(A=[[0.0]], B=[1.0], C=[0.0], order=1, name="EULER")
MIDPOINT_TABLEAU = Tableau(A=[[0, 0], [0.5, 0]], B=[0, 1], C=[0, 0.5], order=2, name="MIDPOINT")
RK4_TABLEAU = Tableau(
    A=[[0, 0, 0, 0], [0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 1, 0]],
    B=[1 / 6, 1 / 3, 1 / 3, 1 / 6], C=[0, 0.5, 0.5, 1], order=4, name="RK4",
)
# Dormand & Prince (1980), "A family of embedded Runge-Kutta formulae", the 5(4) pair "RK5(4)7M".
_DOPRI5_B = [35 / 384, 0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0]
_DOPRI5_B_HAT = [5179 / 57600, 0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40]
DOPRI5_TABLEAU = Tableau(
    A=[
        [0, 0, 0, 0, 0, 0, 0],
        [1 / 5, 0, 0, 0, 0, 0, 0],
        [3 / 40, 9 / 40, 0, 0, 0, 0, 0],
        [44 / 45, -56 / 15, 32 / 9, 0, 0, 0, 0],
        [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0, 0, 0],
        [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656, 0, 0],
        _DOPRI5_B,
    ],
    B=_DOPRI5_B,
    C=[0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1, 1],
    order=5,
    E=np.subtract(_DOPRI5_B, _DOPRI5_B_HAT),
    name="DOPRI5",
)


def rk_step(
    f: Derivative, t: float, y: np.ndarray, h: float, tableau: Tableau, f0: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """One explicit Runge–Kutta step of any tableau.

    Args:
        f: derivative ``f(t, y) -> (dim,)``.
        t: time at the start of the step [s].
        y: state at ``t``, shape ``(dim,)``.
        h: step size [s].
        tableau: the method.
        f0: ``f(t, y)`` when already known (saves one evaluation), else None.

    Returns:
        ``(y_new, K)``: the state at ``t + h`` (shape ``(dim,)``) and the stage derivatives
        ``K`` (shape ``(s, dim)``). ``f`` is called ``s`` times, or ``s - 1`` with ``f0``.
    """
    K = np.empty((tableau.stages, y.shape[0]))
    K[0] = f(t, y) if f0 is None else f0
    for i in range(1, tableau.stages):
        K[i] = f(t + tableau.C[i] * h, y + h * (tableau.A[i, :i] @ K[:i]))
    return y + h * (tableau.B @ K), K


@dataclass
class StepReport:
    """What one :meth:`Integrator.step` call did.

    Attributes:
        steps: accepted internal steps.
        rejected: internal steps rejected by the error control (adaptive methods only).
        evaluations: calls of ``system.derivative``.
        h_last: size of the last accepted internal step [s].
    """

    steps: int = 0
    rejected: int = 0
    evaluations: int = 0
    h_last: float = 0.0


def _non_finite(y: np.ndarray, what: str) -> SimulationError:
    bad = int(np.count_nonzero(~np.isfinite(y)))
    return SimulationError(
        f"state became non-finite: {what} has {bad} NaN/inf of {y.shape[0]} values — "
        "reduce the time step (more substeps) or use a more stable integrator"
    )


class Integrator:
    """Base class: advances a :class:`System` from ``t`` to ``t + dt``.

    Subclasses implement ``_step_impl(system, t, y, dt) -> (y_new, StepReport)``; :meth:`step`
    reads the state, checks the result and writes it back.
    """

    name = "INTEGRATOR"

    def step(self, system: System, t: float, dt: float) -> StepReport:
        """Advance ``system`` from time ``t`` [s] by ``dt`` [s] and store the new state.

        Raises:
            ValueError: ``dt`` is not positive and finite, or the state has the wrong shape.
            SimulationError: the state became non-finite (the caller adds object and frame).
        """
        if not (math.isfinite(dt) and dt > 0.0) or not math.isfinite(t):
            raise ValueError(f"time step must be finite and > 0 (got dt={dt!r} at t={t!r})")
        y = np.array(system.get_state(), dtype=np.float64)
        if y.shape != (system.dim,):
            raise ValueError(f"state must have shape ({system.dim},) (got {y.shape})")
        if not np.all(np.isfinite(y)):
            raise _non_finite(y, "the state before the step")
        # Overflow is detected below and reported as SimulationError, not as a numpy warning.
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            y_new, report = self._step_impl(system, float(t), y, float(dt))
        if not np.all(np.isfinite(y_new)):
            raise _non_finite(y_new, "the new state")
        system.set_state(y_new)
        return report

    def _step_impl(self, system: System, t: float, y: np.ndarray, dt: float):
        raise NotImplementedError  # -> (y_new (dim,), StepReport)


class ExplicitRK(Integrator):
    """Fixed-step explicit Runge–Kutta method given by ``tableau`` (one step of size ``dt``)."""

    def __init__(self, tableau: Tableau):
        self.tableau = tableau
        self.name = tableau.name

    def _step_impl(self, system, t, y, dt):
        y_new, _ = rk_step(system.derivative, t, y, dt, self.tableau)
        return y_new, StepReport(steps=1, evaluations=self.tableau.stages, h_last=dt)


# Internal steps (accepted + rejected) one adaptive call may take. A bake must never hang: a
# discontinuous force (a contact switching on and off) can drive the step size down for ever,
# so past this budget the step fails with advice instead of grinding on.
MAX_ADAPTIVE_STEPS = 2_000


class AdaptiveRK(Integrator):
    """Embedded Runge–Kutta pair with error control; reaches exactly ``t + dt`` per call.

    Args:
        tableau: a tableau with error weights ``E`` (default Dormand–Prince 5(4)).
        rtol: relative tolerance of the local error.
        atol: absolute tolerance of the local error [state units].
        max_steps: internal steps (accepted + rejected) allowed per :meth:`step` call.

    Attributes:
        h_guess: first step size [s] tried by the next call — the controller's last proposal —
            or None before the first call (then a starting step is estimated). :meth:`reset`
            forgets it, e.g. when the same instance starts another simulation.
    """

    SAFETY = 0.9  # aim below the predicted largest step so most steps are accepted
    MIN_FACTOR = 0.2  # largest shrink per step
    MAX_FACTOR = 10.0  # largest growth per step
    MIN_STEP_FRACTION = 1e-12  # of dt: below this, the step size has underflowed

    def __init__(
        self, tableau: Tableau = DOPRI5_TABLEAU, rtol: float = 1e-4, atol: float = 1e-7,
        max_steps: int = MAX_ADAPTIVE_STEPS,
    ):
        if tableau.E is None:
            raise ValueError(f"tableau {tableau.name!r} has no error estimate E (needs a pair)")
        for label, value in (("rtol", rtol), ("atol", atol)):
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{label} must be finite and > 0 (got {value!r})")
        self.tableau, self.name = tableau, tableau.name
        self.rtol, self.atol, self.max_steps = float(rtol), float(atol), int(max_steps)
        self.h_guess: float | None = None

    def reset(self) -> None:
        """Forget the remembered step size."""
        self.h_guess = None

    def _norm(self, e: np.ndarray, y: np.ndarray, y_new: np.ndarray) -> float:
        scale = self.atol + self.rtol * np.maximum(np.abs(y), np.abs(y_new))
        return float(np.sqrt(np.mean((e / scale) ** 2)))

    def _initial_step(self, f: Derivative, t: float, y: np.ndarray, f0: np.ndarray, dt: float):
        """Starting step [s] (Hairer, Nørsett & Wanner, Solving ODEs I, II.4); one more ``f``."""
        d0, d1 = self._norm(y, y, y), self._norm(f0, y, y)
        h0 = 1e-6 * dt if d0 < 1e-5 or d1 < 1e-5 else min(0.01 * d0 / d1, dt)
        d2 = self._norm(f(t + h0, y + h0 * f0) - f0, y, y) / h0
        if max(d1, d2) <= 1e-15:
            h1 = max(1e-6 * dt, h0 * 1e-3)
        else:
            h1 = (0.01 / max(d1, d2)) ** (1.0 / self.tableau.order)
        return min(100.0 * h0, h1, dt)

    def _step_impl(self, system, t, y, dt):
        f, tab, report = system.derivative, self.tableau, StepReport()
        t_end, h_min = t + dt, self.MIN_STEP_FRACTION * dt
        # The embedded solution has order p - 1, so the local error estimate scales as h^p.
        exponent = -1.0 / tab.order
        f0 = f(t, y)
        report.evaluations += 1
        if self.h_guess is None:
            h = self._initial_step(f, t, y, f0, dt)
            report.evaluations += 1
        else:
            h = min(self.h_guess, dt)
        just_rejected = False
        while t < t_end:
            if not np.all(np.isfinite(f0)):
                raise _non_finite(f0, "the derivative")
            if report.steps + report.rejected >= self.max_steps:
                raise SimulationError(
                    f"adaptive integrator needed more than {self.max_steps} internal steps for a "
                    f"{dt:g} s step — raise the tolerance (now rtol={self.rtol:g}), use more "
                    "substeps, or a fixed-step integrator (RK4, SYMPLECTIC_EULER, IMPLICIT)"
                )
            if h < h_min:
                raise SimulationError(
                    f"adaptive step size underflowed to {h:.3g} s (below {h_min:.3g} s) — raise "
                    f"the tolerance (now rtol={self.rtol:g}) or check the forces for a singularity"
                )
            h_wanted = h
            clipped = t_end - (t + h) < h_min  # land exactly on t_end, never leave a sliver
            if clipped:
                h = t_end - t
            y_new, K = rk_step(f, t, y, h, tab, f0=f0)
            report.evaluations += tab.stages - 1
            err = self._norm(h * (tab.E @ K), y, y_new)
            if err < 1.0:  # also False for NaN: an overflowing trial step is rejected
                factor = self.MAX_FACTOR if err == 0.0 else min(
                    self.MAX_FACTOR, self.SAFETY * err**exponent
                )
                if just_rejected:  # the error just proved larger h too optimistic
                    factor = min(1.0, factor)
                t, y = (t_end if clipped else t + h), y_new
                report.steps, report.h_last = report.steps + 1, h
                if tab.fsal:
                    f0 = K[-1]
                else:
                    f0 = f(t, y)
                    report.evaluations += 1
                # A step shortened to hit t_end says nothing against the longer step wanted.
                h = max(h * factor, h_wanted) if clipped else h * factor
                just_rejected = False
            else:
                factor = self.SAFETY * err**exponent if math.isfinite(err) else self.MIN_FACTOR
                h *= max(self.MIN_FACTOR, factor)
                report.rejected += 1
                just_rejected = True
        self.h_guess = h
        return y, report


class SymplecticEuler(Integrator):
    """Semi-implicit (symplectic) Euler for ``y = [x, v]``: ``v += h a(x, v)``; ``x += h v_new``.

    Needs an even ``dim`` and uses only the acceleration half of ``derivative``. First order,
    but energy of an oscillator stays bounded for ``omega * h < 2`` instead of drifting.
    """

    name = "SYMPLECTIC_EULER"

    def _step_impl(self, system, t, y, dt):
        n = y.shape[0] // 2
        if y.shape[0] != 2 * n:
            raise ValueError(f"symplectic Euler needs y = [x, v] with even dim (got {y.shape[0]})")
        v_new = y[n:] + dt * system.derivative(t, y)[n:]
        report = StepReport(steps=1, evaluations=1, h_last=dt)
        return np.concatenate([y[:n] + dt * v_new, v_new]), report


def bicgstab(
    matvec: Callable[[np.ndarray], np.ndarray], b: np.ndarray, rtol: float = 1e-8,
    max_iterations: int = 200,
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
        raise _non_finite(b, "the linear system's right-hand side")
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


class ImplicitEuler(Integrator):
    """Linearly implicit (Rosenbrock) Euler for stiff systems: one Newton step of backward Euler.

    Solves ``(I - h J) dy = h f(t, y)`` with ``J = df/dy`` at ``(t, y)`` and sets ``y += dy``:
    first order, stable for any ``h`` on damped and oscillating linear systems (it damps them).
    ``J u`` is matrix-free, ``(f(t, y + eps u) - f(t, y)) / eps`` with
    ``eps = sqrt(machine eps) * (1 + |y|) / |u|``, unless the system defines
    ``jacobian_vector(t, y, u) -> (dim,)`` (then used instead and not counted in
    ``StepReport.evaluations``). Linear systems are solved by :func:`bicgstab`.

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
            raise _non_finite(f0, "the derivative")
        jacobian_vector = getattr(system, "jacobian_vector", None)
        y_scale = 1.0 + float(np.linalg.norm(y))

        def jv(u: np.ndarray) -> np.ndarray:
            if jacobian_vector is not None:
                return np.asarray(jacobian_vector(t, y, u), dtype=np.float64)
            u_norm = float(np.linalg.norm(u))
            if u_norm == 0.0:
                return np.zeros_like(u)
            eps = self.FD_SCALE * y_scale / u_norm
            report.evaluations += 1
            return (system.derivative(t, y + eps * u) - f0) / eps

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


INTEGRATORS = ("EULER", "SYMPLECTIC_EULER", "MIDPOINT", "RK4", "RK45", "IMPLICIT")


def make_integrator(name: str, tolerance: float = 1e-4) -> Integrator:
    """Integrator for one of :data:`INTEGRATORS`.

    Args:
        name: identifier from :data:`INTEGRATORS`.
        tolerance: relative tolerance of ``RK45`` (absolute tolerance ``tolerance * 1e-3``, in
            state units: metres and metres per second) and of the ``IMPLICIT`` linear solve;
            ignored by the fixed-step explicit methods. ``SYMPLECTIC_EULER`` and ``IMPLICIT``
            expect the ``y = [x, v]`` convention.

    Raises:
        ValueError: unknown ``name`` or a ``tolerance`` that is not finite and > 0.
    """
    if name not in INTEGRATORS:
        raise ValueError(f"unknown integrator {name!r}; choose one of {', '.join(INTEGRATORS)}")
    if not (math.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"integrator tolerance must be finite and > 0 (got {tolerance!r})")
    if name == "RK45":
        return AdaptiveRK(DOPRI5_TABLEAU, rtol=tolerance, atol=tolerance * 1e-3)
    if name == "IMPLICIT":  # physanim systems follow the [x, v] convention
        return ImplicitEuler(rtol=tolerance, second_order=True)
    if name == "SYMPLECTIC_EULER":
        return SymplecticEuler()
    tableau = {"EULER": EULER_TABLEAU, "MIDPOINT": MIDPOINT_TABLEAU, "RK4": RK4_TABLEAU}[name]
    return ExplicitRK(tableau)
