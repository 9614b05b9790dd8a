"""Second-order implicit steps for spring meshes: BDF2, as Baraff & Witkin steps from an
extrapolated state.

Backward Euler damps every motion by a factor 1 / sqrt(1 + (omega h)^2) per step: a cloth
swinging with a 2 s period at 24 steps a second loses a third of its amplitude each swing, a
fifth at 48. The second-order backward differentiation formula

    x1 - 4/3 x0 + 1/3 x_-1 = 2/3 h v1,    v1 - 4/3 v0 + 1/3 v_-1 = 2/3 h M^-1 f(x1, v1)

is as stable (A-stable, and it still damps the mesh's fastest, unresolved motions) but damps a
resolved motion by about (omega h)^4 / 4 per step: that swing keeps 99.7 % of its amplitude per
period at 24 steps a second. With x^ = (4 x0 - x_-1) / 3, v^ = (4 v0 - v_-1) / 3 and
h^ = 2 h / 3 the formula reads x1 = x^ + h^ v1, v1 = v^ + h^ M^-1 f(x1, v1): one backward Euler
step of h^ from (x^, v^). So a BDF2 step is a :class:`~.implicit.BaraffWitkin` step from the
extrapolated state — the same linearisation, assembled matrix, multigrid and Newton safeguard —
with each pinned vertex given the velocity that puts it where backward Euler would, at its pin.

The previous step's start is the history. A vertex whose state was changed between the steps
(pins put on their targets, self-collision, strain limiting, a landing round) starts its history
again as if it had moved at its current velocity (x_-1 = x0 - h v0, v_-1 = v0); the first step,
a step after the sub-step length changed, and steps with vertices on colliders or coupled to
bodies are backward Euler steps (contacts, friction and two-way coupling prescribe and exchange
velocities over the whole step, as backward Euler takes it).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import row_all
from .implicit import BaraffWitkin
from .implicit_parts import BaraffWitkinSystem, positions_and_velocities


@dataclass
class History:
    """What a :class:`BDF2` stepper keeps of its last step.

    Attributes:
        t, h: its start time and length [s] (None before the first step).
        start: ``(x, v)`` (n, 3) each at its start. end: ``(x, v)`` it returned.
        before: ``(x_-1, v_-1)`` it used, None for a backward Euler step (a step solved again
            from the same start, as a landing round does, uses the same).
    """

    t: float | None = None
    h: float | None = None
    start: tuple | None = None
    end: tuple | None = None
    before: tuple | None = None


class _Extrapolated:
    """The system as the backward Euler step of h^ from (x^, v^) must see it: pinned vertices
    move to where backward Euler from (x0, h) puts them, x0 + h u, at u' = (x0 + h u - x^) / h^;
    everything else is the system's own."""

    def __init__(self, system: BaraffWitkinSystem, x0: np.ndarray, h: float, x_hat: np.ndarray,
                 h_hat: float):
        self._system, self._x0, self._h, self._x_hat, self._h_hat = system, x0, h, x_hat, h_hat

    def __getattr__(self, name):
        return getattr(self._system, name)

    def pinned_velocity(self, t: float) -> np.ndarray:
        u = self._system.pinned_velocity(t)
        return (self._x0 + self._h * u - self._x_hat) / self._h_hat


class BDF2(BaraffWitkin):
    """Second-order implicit stepper for spring meshes (module docstring); the arguments are
    :class:`~.implicit.BaraffWitkin`'s."""

    name = "BDF2"

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.history = History()
        #: whether the last step was a BDF2 step (False: backward Euler)
        self.last_second_order = False

    def __setstate__(self, state):  # a stepper pickled before it kept these
        self.__dict__.update(state)
        self.__dict__.setdefault("history", History())
        self.__dict__.setdefault("last_second_order", False)

    def _step_impl(self, system: BaraffWitkinSystem, t: float, y: np.ndarray, h: float):
        x0, v0 = positions_and_velocities(y)
        before = self._before(t, h, x0, v0)
        coupled = len(system.contact) or len(system.bodies) or getattr(system, "coupled", False)
        self.last_second_order = before is not None and not coupled
        if not self.last_second_order:
            y1, report = super()._step_impl(system, t, y, h)
        else:
            x_hat = (4.0 * x0 - before[0]) / 3.0
            v_hat = (4.0 * v0 - before[1]) / 3.0
            h_hat = 2.0 * h / 3.0
            # the step of h^ ends where this one does, at t + h
            y1, report = super()._step_impl(_Extrapolated(system, x0, h, x_hat, h_hat),
                                            t + h - h_hat,
                                            np.concatenate([x_hat.ravel(), v_hat.ravel()]),
                                            h_hat)
        x1, v1 = positions_and_velocities(y1)
        self.history.end = (x1.copy(), v1.copy())
        return y1, report

    def _before(self, t: float, h: float, x0: np.ndarray, v0: np.ndarray):
        """(x_-1, v_-1) for the step of h from (x0, v0) at t, or None for a backward Euler one;
        moves the history on to this step."""
        past = self.history
        if past.t == t and past.h == h and past.start is not None and \
                np.array_equal(past.start[0], x0) and np.array_equal(past.start[1], v0):
            return past.before  # the same step solved again
        before = None
        if past.end is not None and past.h == h and \
                abs(t - (past.t + h)) <= 1e-9 * max(1.0, abs(t)):  # the next step
            same = row_all(past.end[0] == x0) & row_all(past.end[1] == v0)
            if same.any():
                before = (np.where(same[:, None], past.start[0], x0 - h * v0),
                          np.where(same[:, None], past.start[1], v0))
        self.history = History(t, h, (x0.copy(), v0.copy()), None, before)
        return before
