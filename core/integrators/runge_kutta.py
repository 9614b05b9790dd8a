"""Explicit integrators: Butcher tableaux (Euler, midpoint, RK4, Dormand-Prince 5(4)) run by one
generic :func:`rk_step`, the adaptive RK45 built on the embedded pair, and symplectic Euler."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import SimulationError
from .base import (Derivative, Integrator, PointSystem, StepReport, all_finite, check_step,
                   finite_sum, is_a, non_finite, quiet)


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
        stable_h_omega: the method's step bound on an undamped oscillator (see
            :attr:`Integrator.stable_h_omega`), or None.

    The arrays are copied and made read-only. Raises ValueError naming the bad field.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    order: int
    E: np.ndarray | None = None
    name: str = ""
    stable_h_omega: float | None = None

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


# Euler and midpoint grow at any step on an undamped spring: their bounds keep the growth per
# frame small enough for damping to win. RK4's true bound is 2.83; 2.5 leaves a margin.
EULER_TABLEAU = Tableau(A=[[0.0]], B=[1.0], C=[0.0], order=1, name="EULER", stable_h_omega=0.1)
MIDPOINT_TABLEAU = Tableau(A=[[0, 0], [0.5, 0]], B=[0, 1], C=[0, 0.5], order=2, name="MIDPOINT",
                           stable_h_omega=0.5)
RK4_TABLEAU = Tableau(
    A=[[0, 0, 0, 0], [0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 1, 0]],
    B=[1 / 6, 1 / 3, 1 / 3, 1 / 6], C=[0, 0.5, 0.5, 1], order=4, name="RK4",
    stable_h_omega=2.5,
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


class ExplicitRK(Integrator):
    """Fixed-step explicit Runge–Kutta method given by ``tableau`` (one step of size ``dt``)."""

    def __init__(self, tableau: Tableau):
        self.tableau = tableau
        self.name = tableau.name
        self.stages = tableau.stages
        self.stable_h_omega = tableau.stable_h_omega

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
        self.tableau, self.name, self.stages = tableau, tableau.name, tableau.stages
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
                raise non_finite(f0, "the derivative")
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
    stable_h_omega = 1.9  # bounded for h * omega < 2; a margin below it

    def step(self, system, t: float, dt: float) -> StepReport:
        """As :meth:`Integrator.step`; a :class:`~.base.PointSystem` is stepped on its stored
        arrays (the same values to the bit, without packing y: a particle step's state is
        read once instead of copied three times)."""
        if not is_a(system, PointSystem):
            return super().step(system, t, dt)
        check_step(t, dt)
        x, v = system.points()
        with quiet():
            a = system.acceleration(float(t), x, v)
            into = system.new_points()
            v_new, x_new = _kick_drift(a, x, v, float(dt), *(
                (a, np.empty_like(x)) if into is None else (into[1], into[0])))
            # a non-finite value before the step leaves one after it (the step adds to each
            # value), so the state before is read only to say which it was
            if not (finite_sum(x_new) and finite_sum(v_new)):
                if not all_finite(x, v):
                    raise non_finite(np.concatenate([x.ravel(), v.ravel()]),
                                     "the state before the step")
                if not all_finite(x_new, v_new):
                    raise non_finite(np.concatenate([x_new.ravel(), v_new.ravel()]),
                                     "the new state")
        system.set_points(x_new, v_new)
        return StepReport(steps=1, evaluations=1, h_last=dt)

    def _step_impl(self, system, t, y, dt):
        n = y.shape[0] // 2
        if y.shape[0] != 2 * n:
            raise ValueError(f"symplectic Euler needs y = [x, v] with even dim (got {y.shape[0]})")
        a = system.derivative(t, y)[n:]
        out = np.empty_like(y)  # [x_new, v_new], filled without temporaries
        _kick_drift(a, y[:n], y[n:], dt, out[n:], out[:n])
        return out, StepReport(steps=1, evaluations=1, h_last=dt)


def _kick_drift(a, x, v, dt: float, v_out, x_out):
    """Symplectic Euler's arithmetic: v_out = a dt + v, then x_out = v_out dt + x (``v_out``
    may be ``a``); returns (v_out, x_out)."""
    np.multiply(a, dt, out=v_out)
    v_out += v
    np.multiply(v_out, dt, out=x_out)
    x_out += x
    return v_out, x_out
