"""Particles at rest, which the sub-steps skip while nothing that could move them changes.

A sub-step is, for each particle on its own, a function of its position and velocity: the
same gravity, the same still colliders, the same integrator give the same numbers. A particle
the last sub-step left exactly where it was with exactly the velocity it had (a grain lying
on a still ground: the contact force cancels gravity, friction holds it; a particle floating
still without gravity) is a fixed point of that function, and every later sub-step computing
it would give the same bits again. So while the sub-steps stay the same function, such
particles are left out of them: a settled pile costs its awake particles, the births and
deaths, not every grain in it. The results are the same to the bit (tested).

The sub-step is that function only when each particle moves on its own and the inputs are
those it rested under (:func:`conditions`): gravity alone (no force object, interaction,
particle collision, spring, constraint or tie), explicit or symplectic Euler or the midpoint
method, and the same colliders, each still over the interval (no motion, no deformation) and
unchanged. Anything else — a collider that moves or is keyed, gravity keyed, a force switched
on — wakes every particle for a sub-step (:class:`Rest`), after which those still at rest
sleep again. To the bit also means no product whose rounding depends on how many particles
it is given: BLAS rounds a one-row product unlike a several-row one
(:func:`~..transforms.transform_points` maps a lone point as a row of two), and RK4's sum of
its stages is one product over the whole state.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..contact import same_frames

# integrators whose step is a function of each particle alone, to the bit: RK4's weighted sum
# of its stages is one BLAS product over the whole state, whose last values round by the
# state's length
FIXED_STEP = ("EULER", "SYMPLECTIC_EULER", "MIDPOINT")


@dataclass(frozen=True)
class Conditions:
    """What a sub-step is a function of: the integrator, gravity (3,), the sub-step [s] and
    the colliders' frames (:class:`~..contact.ColliderFrame`), each still."""

    integrator: str
    gravity: tuple
    h: float
    colliders: tuple

    def same_as(self, other: Conditions | None) -> bool:
        if other is self:  # the frame's other sub-steps
            return True
        return (other is not None and (self.integrator, self.gravity, self.h) ==
                (other.integrator, other.gravity, other.h) and
                same_frames(self.colliders, other.colliders))


def conditions(integrator: str, gravity: np.ndarray, h: float, inputs, paths: list,
               alone: bool) -> Conditions | None:
    """The conditions of a frame interval's sub-steps, or None when a particle's sub-step is
    not a function of its own position and velocity under them (``alone``: the caller found
    no springs, constraints or ties among the particles, and no emitter that makes springs)."""
    if (not alone or integrator not in FIXED_STEP or inputs.forces or inputs.interactions
            or inputs.collisions or not all(path.still for path in paths)):
        return None
    return Conditions(integrator, tuple(gravity.tolist()), float(h),
                      tuple(path.frame for path in paths))


def unchanged(x0, v0, x1, v1) -> np.ndarray:
    """(n,) whether each row of x1, v1 equals x0, v0: ``row_all(x1 == x0) & row_all(v1 ==
    v0)``, column by column, velocities first (gravity changes them in flight), stopping when
    no row is left (one compare for particles in the air instead of six)."""
    out = None
    for a, b in ((v1, v0), (x1, x0)):
        for k in (2, 0, 1):
            same = a[:, k] == b[:, k]
            if out is None:
                out = same
            else:
                out &= same
            if not out.any():
                return out
    return out


class Rest:
    """Which particles of a state are at rest (a mask aligned with its particles), under which
    :class:`Conditions`; the solver keeps it aligned through deaths and births."""

    def __init__(self):
        self.state = None
        self.mask: np.ndarray | None = None
        self.conditions: Conditions | None = None

    def awake(self, state, now: Conditions | None) -> np.ndarray | None:
        """The indices of the particles a sub-step under ``now`` must compute, or None for
        all of them (nobody rests, or the conditions changed: everybody wakes)."""
        if (now is None or state is not self.state or self.mask is None or
                len(self.mask) != state.particle_count or not now.same_as(self.conditions)):
            self.mask = None
            return None
        if not self.mask.any():
            return None
        return np.flatnonzero(~self.mask)

    def settle(self, state, awake: np.ndarray | None, x0, v0, x1, v1,
               now: Conditions | None) -> None:
        """After a sub-step under ``now``: of the particles it computed (``awake``; None: all),
        from x0, v0 to x1, v1, those left exactly as they were rest from now on."""
        self.rested(state, awake, None if now is None else unchanged(x0, v0, x1, v1), now)

    def rested(self, state, awake: np.ndarray | None, still: np.ndarray | None,
               now: Conditions | None) -> None:
        """As :meth:`settle`, where the caller compared them: ``still`` (of ``awake``; None
        when ``now`` is None) which were left exactly as they were."""
        if now is None:
            self.mask = None
            return
        if awake is None:
            self.mask = still
        else:
            self.mask[awake] = still
        self.state, self.conditions = state, now

    def keep(self, alive: np.ndarray) -> None:
        """The particles where ``alive`` is False died."""
        if self.mask is not None:
            self.mask = self.mask[alive]

    @property
    def count(self) -> int:
        """How many particles are at rest."""
        return int(np.count_nonzero(self.mask)) if self.mask is not None else 0

    def born(self, count: int) -> None:
        """``count`` particles were born (awake) after the others."""
        if self.mask is not None and count:
            self.mask = np.concatenate([self.mask, np.zeros(count, bool)])
