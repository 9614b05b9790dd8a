"""Piecewise-linear curves over a parameter in [0, 1] (a particle's life fraction)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LifeCurve:
    """Values of ``channels`` components at increasing ``positions`` in [0, 1], linear between.

    Args:
        positions: (k,) stop positions, non-decreasing, each in [0, 1].
        values: (k, channels) value at each stop.

    Before the first stop the first value holds, after the last the last value holds (as a
    Blender color ramp in linear mode does).
    """

    positions: tuple[float, ...]
    values: tuple[tuple[float, ...], ...]

    def __post_init__(self):
        pos = np.asarray(self.positions, dtype=np.float64)
        val = np.asarray(self.values, dtype=np.float64)
        if pos.ndim != 1 or len(pos) == 0:
            raise ValueError(f"life curve needs at least one stop (got {len(pos)})")
        if val.ndim != 2 or len(val) != len(pos):
            raise ValueError(f"life curve has {len(pos)} positions but values of shape {val.shape}")
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(val))):
            raise ValueError(f"life curve stops must be finite (got {pos.tolist()}, {val.tolist()})")
        if np.any(pos < 0.0) or np.any(pos > 1.0):
            raise ValueError(f"life curve positions must lie in [0, 1] (got {pos.tolist()})")
        if np.any(np.diff(pos) < 0.0):
            raise ValueError(f"life curve positions must not decrease (got {pos.tolist()})")

    @classmethod
    def constant(cls, *value: float) -> LifeCurve:
        return cls((0.0,), (tuple(float(v) for v in value),))

    @property
    def is_constant(self) -> bool:
        """Whether every stop holds the same value (the curve does not depend on t)."""
        return all(v == self.values[0] for v in self.values)

    @property
    def channels(self) -> int:
        return len(self.values[0])

    def evaluate(self, t: np.ndarray, dtype=np.float64) -> np.ndarray:
        """(n, channels) curve values at parameters ``t`` (n,), as ``dtype`` (float32: the
        float64 values rounded, as ``astype`` rounds them)."""
        t = np.asarray(t, dtype=np.float64)
        pos = np.asarray(self.positions)
        val = np.asarray(self.values)
        if self.is_constant:  # the defaults: one value whatever t is (tiled: a broadcast
            return np.tile(val[0].astype(dtype), t.shape + (1,))  # fill is 10 x slower)
        out = np.empty(t.shape + (val.shape[1],), dtype)
        for c in range(val.shape[1]):  # loop over channels (<= 4), vectorised over particles
            out[..., c] = np.interp(t, pos, val[:, c])
        return out
