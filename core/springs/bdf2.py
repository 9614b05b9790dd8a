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
extrapolated state — the same linearisation, assembled matrix, multigrid, Newton safeguard,
contacts and friction — with every prescribed velocity (a pin's, a pressed vertex's along its
normal, a vertex static friction holds, one landing on a collider) turned into the one that
ends the step where backward Euler's prescription would: w' = (x0 + h w - x^) / h^.

The previous step's start is the history. A vertex whose state was changed between the steps
(pins put on their targets, a collision's response, self-collision, strain limiting) takes as
its history a step that ends at its state now with the last step's velocity change dv
(v_-1 = v0 - dv, x_-1 = x0 - h v0 + h dv / 2: exact for a constant acceleration). The first
step, a step after the sub-step length changed, and steps of a mesh that exchanges impulses
with a body (two-way attachments, contacts with bodies: the coupling hands over the impulses
of a whole step, as backward Euler takes it) are backward Euler steps.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..transforms import dot_rows, row_all
from .implicit import BaraffWitkin
from .implicit_parts import BaraffWitkinSystem, VelocityFilter, positions_and_velocities


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


class BDF2(BaraffWitkin):
    """Second-order implicit stepper for spring meshes (module docstring); the arguments are
    :class:`~.implicit.BaraffWitkin`'s."""

    name = "BDF2"
    # its solves' relative residual: at implicit Euler's 1e-2 the solve's error outgrew BDF2's
    # own at 8 sub-steps per frame (a plate carried by the wind: its error fell 71 x from 2 to
    # 4 sub-steps, then rose), and second order is what BDF2 is chosen for
    TOLERANCE = 1e-3

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.history = History()
        #: whether the last step was a BDF2 step (False: backward Euler)
        self.last_second_order = False
        self._start: tuple | None = None  # (x0, v0, h, x^) of a BDF2 step while it is solved

    def _step_impl(self, system: BaraffWitkinSystem, t: float, y: np.ndarray, h: float):
        x0, v0 = positions_and_velocities(y)
        before = self._before(t, h, x0, v0)
        coupled = system.coupled or (
            len(system.bodies) and np.isin(system.contact.collider, system.bodies).any())
        self.last_second_order = before is not None and not coupled
        if not self.last_second_order:
            y1, report = super()._step_impl(system, t, y, h)
        else:
            x_hat = (4.0 * x0 - before[0]) / 3.0
            v_hat = (4.0 * v0 - before[1]) / 3.0
            h_hat = 2.0 * h / 3.0
            # the step of h^ ends where this one does, at t + h
            self._start = (x0, v0, h, x_hat)
            try:
                y1, report = super()._step_impl(system, t + h - h_hat,
                                                np.concatenate([x_hat.ravel(), v_hat.ravel()]),
                                                h_hat)
            finally:
                self._start = None
        x1, v1 = positions_and_velocities(y1)
        self.history.end = (x1.copy(), v1.copy())
        return y1, report

    def _constraints(self, system: BaraffWitkinSystem, t: float, h: float, v0: np.ndarray,
                     f0: np.ndarray, slipping: np.ndarray | None = None,
                     leaving: np.ndarray | None = None) -> VelocityFilter:
        """Backward Euler's filter (:meth:`.implicit.BaraffWitkin._constraints`) from the
        extrapolated state, its prescribed velocities w turned into the ones that end a BDF2
        step where w ends a backward Euler step: w' = (x0 + h w - x^) / h^ — all three
        directions of pinned and held vertices, the normal of pressed ones."""
        out = super()._constraints(system, t, h, v0, f0, slipping, leaving)
        if self._start is None:
            return out
        x0, _, h0, x_hat = self._start
        turned = (x0 + h0 * (v0 + out.given) - x_hat) / h - v0
        given = out.given.copy()
        fixed = out.free_scale[:, 0] == 0.0
        given[fixed] = turned[fixed]
        sliding = np.ones(len(out.pressed), bool) if out.stuck is None else ~out.stuck
        rows, normal = out.pressed[sliding], out.normal[sliding]
        given[rows] = dot_rows(turned[rows], normal)[:, None] * normal
        return replace(out, given=given)

    def _start_energy(self, system: BaraffWitkinSystem, x: np.ndarray, v: np.ndarray) -> float:
        """The energy of the step's real start (x0, v0), not of the extrapolated state the
        step of h^ starts from: extrapolating a turning edge stretches it, and that spring
        energy let steps that gained energy pass the Newton safeguard unrefined (a flag's
        flapping edges stretched to three times their length at one step per frame)."""
        if self._start is None:
            return super()._start_energy(system, x, v)
        return super()._start_energy(system, self._start[0], self._start[1])

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
            # changed rows: a step before this one ending at their state now, accelerating by
            # the last step's velocity change dv (without it this step would give them only
            # 2/3 of their forces' impulse); exact for a constant acceleration
            dv = past.end[1] - past.start[1]
            before = (np.where(same[:, None], past.start[0], x0 - h * v0 + 0.5 * h * dv),
                      np.where(same[:, None], past.start[1], v0 - dv))
        self.history = History(t, h, (x0.copy(), v0.copy()), None, before)
        return before
