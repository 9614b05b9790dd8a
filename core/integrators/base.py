"""What every integrator shares: the system interface it sees (Witkin & Baraff's), the report of
a step, and the base class that reads, checks and writes the state around each step."""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from ..errors import SimulationError

Derivative = Callable[[float, np.ndarray], np.ndarray]


class System(Protocol):
    """What an integrator needs (Witkin & Baraff): ``dim``; ``get_state() -> (dim,)`` float64;
    ``set_state(y)``; ``derivative(t, y) -> (dim,)``, a pure function of ``t`` [s] and ``y``.

    Optional capabilities are protocols of their own, which a stepper tests with ``isinstance``:
    :class:`JacobianSystem` (an exact ``J u`` for implicit Euler), :class:`PointSystem`
    (positions and velocities as they are stored, for symplectic Euler). Steppers that need more than
    this interface name their own protocol (the spring meshes' ``BaraffWitkinSystem``).
    """

    dim: int

    def get_state(self) -> np.ndarray: ...

    def set_state(self, y: np.ndarray) -> None: ...

    def derivative(self, t: float, y: np.ndarray) -> np.ndarray: ...


@runtime_checkable
class JacobianSystem(System, Protocol):
    """A :class:`System` that also knows the product of its Jacobian with a vector:
    ``jacobian_vector(t, y, u) -> (dim,)`` = ``df/dy (t, y) u``. Implicit Euler uses it instead
    of finite differences of ``derivative``."""

    def jacobian_vector(self, t: float, y: np.ndarray, u: np.ndarray) -> np.ndarray: ...


@runtime_checkable
class PointSystem(System, Protocol):
    """A :class:`System` of points whose state is y = [x, v] with x' = v, also seen as it is
    stored: ``points() -> (x, v)`` (n, 3) each, read only; ``acceleration(t, x, v) -> (n, 3)``,
    the second half of ``derivative`` (to the bit), as a fresh array the caller may overwrite;
    ``set_points(x, v)`` stores new arrays; ``new_points() -> (x, v) | None``: where the step is
    to write the new positions and velocities (None: arrays of its own). Symplectic Euler steps
    it without packing the state into y or copying the velocities into a derivative."""

    def points(self) -> tuple[np.ndarray, np.ndarray]: ...

    def new_points(self) -> tuple[np.ndarray, np.ndarray] | None: ...

    def acceleration(self, t: float, x: np.ndarray, v: np.ndarray) -> np.ndarray: ...

    def set_points(self, x: np.ndarray, v: np.ndarray) -> None: ...


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


def non_finite(y: np.ndarray, what: str) -> SimulationError:
    bad = int(np.count_nonzero(~np.isfinite(y)))
    return SimulationError(
        f"state became non-finite: {what} has {bad} NaN/inf of {y.shape[0]} values — "
        "reduce the time step (more substeps) or use a more stable integrator"
    )


def check_step(t: float, dt: float) -> None:
    if not (math.isfinite(dt) and dt > 0.0) or not math.isfinite(t):
        raise ValueError(f"time step must be finite and > 0 (got dt={dt!r} at t={t!r})")


_KINDS: dict = {}


def is_a(system, protocol) -> bool:
    """``isinstance(system, protocol)`` for a runtime-checkable protocol, remembered per class:
    the structural check reads every member of the protocol (about 30 us in Python 3.11), once
    per step of every system otherwise — a tenth of a 10,000-particle step. Systems are classes
    whose methods do not come and go per instance."""
    key = (type(system), protocol)
    known = _KINDS.get(key)
    if known is None:
        known = _KINDS[key] = isinstance(system, protocol)
    return known


def all_finite(*arrays: np.ndarray) -> bool:
    return all(bool(np.isfinite(a).all()) for a in arrays)


class _Quiet:
    """``np.errstate(over="ignore", invalid="ignore", divide="ignore")`` (underflow as it was)
    in a quarter of its time where numpy keeps its error modes in one object (numpy 1.x:
    entering and leaving errstate cost about 3 us, a hundredth of a 10,000-particle step).
    Every step's arithmetic runs inside it: non-finite results are found and named, not
    warned about."""

    __slots__ = ("_old",)
    # numpy 1.x's error mask: 3 bits per kind (divide at 0, over 3, under 6, invalid 9),
    # 0 = ignore
    _MASK = ~((7 << 0) | (7 << 3) | (7 << 9))

    def __enter__(self) -> None:
        old = self._old = np.geterrobj()
        np.seterrobj([old[0], old[1] & self._MASK, old[2]])

    def __exit__(self, *exc) -> None:
        np.seterrobj(self._old)


def quiet():
    """A context in which overflow, invalid values and division by zero pass silently (as
    ``np.errstate`` with those three ignored)."""
    if hasattr(np, "seterrobj"):
        return _Quiet()
    return np.errstate(over="ignore", invalid="ignore", divide="ignore")  # (numpy 2)


def finite_sum(a: np.ndarray) -> bool:
    """Whether the sum of ``a``'s values is finite: True means every value is (a NaN or an
    infinity makes the sum NaN or infinite); False, that one is not or that the sum of finite
    values overflowed (call under ``np.errstate(over="ignore")``). One pass, no temporary:
    a faster first test than :func:`all_finite`."""
    return math.isfinite(np.add.reduce(a, axis=None))


class Integrator:
    """Base class: advances a :class:`System` from ``t`` to ``t + dt``.

    Subclasses implement ``_step_impl(system, t, y, dt) -> (y_new, StepReport)``; :meth:`step`
    reads the state, checks the result and writes it back.
    """

    name = "INTEGRATOR"
    #: state-sized arrays one step holds besides the state (stages, residuals): what a bake's
    #: memory estimate multiplies the state by
    stages = 1
    #: largest ``h * omega`` on an undamped spring of angular frequency ``omega`` for which a
    #: step stays bounded over a frame (methods that grow at any step get the bound that keeps
    #: the growth small enough for damping to win); None: no bound (implicit or adaptive)
    stable_h_omega: float | None = None

    def step(self, system: System, t: float, dt: float) -> StepReport:
        """Advance ``system`` from time ``t`` [s] by ``dt`` [s] and store the new state.

        Raises:
            ValueError: ``dt`` is not positive and finite, or the state has the wrong shape.
            SimulationError: the state became non-finite (the caller adds object and frame).
        """
        check_step(t, dt)
        y = np.array(system.get_state(), dtype=np.float64)
        if y.shape != (system.dim,):
            raise ValueError(f"state must have shape ({system.dim},) (got {y.shape})")
        if not all_finite(y):
            raise non_finite(y, "the state before the step")
        # Overflow is detected below and reported as SimulationError, not as a numpy warning.
        with quiet():
            y_new, report = self._step_impl(system, float(t), y, float(dt))
        if not all_finite(y_new):
            raise non_finite(y_new, "the new state")
        system.set_state(y_new)
        return report

    def _step_impl(self, system: System, t: float, y: np.ndarray, dt: float):
        raise NotImplementedError  # -> (y_new (dim,), StepReport)
