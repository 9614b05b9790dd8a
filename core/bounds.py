"""Physically meaningful bounds on a simulation's state.

A bake whose state leaves them (a particle 1e34 m away after an absurd gravity, a cloth flung
at light speed) is a failure naming the object, the frame and the value — never a finished bake
full of garbage. Both bounds are scene settings (Scene > PhysAnim > Limits).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

DEFAULT_POSITION = 1.0e5  # [m]: 100 km from the world origin
DEFAULT_SPEED = 1.0e5  # [m/s]: the emitters' fastest launch speed
_COMPONENT = (1.0 - 1e-12) / math.sqrt(3.0)  # of the speed limit: no faster component passes


@dataclass(frozen=True)
class StateBounds:
    """Largest position coordinate [m] and speed [m/s] a simulated point may have."""

    position: float = DEFAULT_POSITION
    speed: float = DEFAULT_SPEED

    def __post_init__(self):
        for key in ("position", "speed"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"the {key} bound must be finite and > 0 (got {value})")

    def within(self, x: np.ndarray, v: np.ndarray) -> bool:
        """True when every point (x, v: (n, 3), n > 0) is finite and within the bounds, found
        by four reductions without a temporary: every coordinate within the world bound,
        every velocity component within the speed limit / sqrt(3) (so every speed is within
        it); a NaN fails every comparison. False may still be within (a fast component):
        :meth:`violation` tells."""
        p, s = self.position, self.speed * _COMPONENT
        return bool(x.max() <= p and -x.min() <= p and v.max() <= s and -v.min() <= s)

    def violation(self, x: np.ndarray, v: np.ndarray) -> tuple[int, str] | None:
        """The first point (index) outside the bounds or non-finite, and what is wrong with it
        (a phrase naming the value and the bound); None when every point is inside.

        Args:
            x: (n, 3) positions [m]. v: (n, 3) velocities [m/s].
        """
        if len(x) == 0 or self.within(x, v):
            return None
        with np.errstate(invalid="ignore", over="ignore"):
            speed2 = np.einsum("ij,ij->i", v, v)
            if np.abs(x).max() <= self.position and speed2.max() <= self.speed * self.speed:
                return None
            far = ~(np.abs(x) <= self.position).all(axis=1)  # NaN fails the test too
            fast = ~(speed2 <= self.speed * self.speed)
        bad = far | fast
        if not bad.any():
            return None
        i = int(np.argmax(bad))
        if not np.isfinite(x[i]).all():
            return i, f"position became {np.array2string(x[i], precision=4)}"
        if not np.isfinite(v[i]).all():
            return i, f"velocity became {np.array2string(v[i], precision=4)}"
        if far[i]:
            return i, (f"position {np.array2string(x[i], precision=4)} m is beyond the world "
                       f"bound (±{self.position:g} m)")
        big = float(np.abs(v[i]).max())  # scaled: |v|^2 may overflow where |v| does not
        return i, (f"speed {big * float(np.linalg.norm(v[i] / big)):.4g} m/s is beyond the speed limit "
                   f"({self.speed:g} m/s)")


DEFAULT_BOUNDS = StateBounds()
