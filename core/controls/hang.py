"""Slow in, slow out and exaggeration (Lasseter) on a simulated body's flights: hang time at the
apex of a jump and a bounce exaggeration factor — drawn on top of the simulation, which stays
as it was (contacts happen where and when they were simulated).

A *flight* is a run of frames in free fall: between two samples the velocity changes by
gravity times the time between them (within a slack), and the body rises then falls (it has an
apex). Both controls act inside each flight only, keeping its take-off and landing frames and
poses, so a body still meets what it hits on the simulated frame:

- Hang time h (0 <= h < 1) eases the flight's clock around the apex: on the way up the shown
  time is s = a w(u / a) with w(x) = x + (h / pi) sin(pi x), mirrored on the way down (u: time
  since take-off, a: time of the apex). w(0) = 0, w(1) = 1, w'(0) = 1 + h, w'(1) = 1 - h: the body
  leaves and lands a little faster, lingers at the apex at (1 - h) of its speed, and the flight
  lasts as long as simulated. The path in space is the simulated one.
- Exaggeration k scales each flight's height above the line from its take-off to its landing
  (along "up", against gravity) by k: a bounce k times as high, in the same time.

Positions between samples come from a cubic Hermite curve whose tangents are the three-point
derivatives (exact for the parabola of a free flight); orientations by slerp.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..transforms import slerp

#: Velocity change beyond gravity that ends a flight [m/s], and its part proportional to speed.
SLACK = 0.05
SLACK_FRACTION = 0.02
MIN_FLIGHT_SAMPLES = 4  # fewer samples than this are no jump to ease


@dataclass(frozen=True)
class FlightSettings:
    """Attributes:
        hang_time: 0 (off) .. < 1: the speed at the apex is (1 - hang_time) of the simulated.
        exaggeration: > 0: flight heights above the take-off-to-landing line times this (1:
            off).
    """

    hang_time: float = 0.0
    exaggeration: float = 1.0

    def __post_init__(self):
        if not (math.isfinite(self.hang_time) and 0.0 <= self.hang_time < 1.0):
            raise ValueError(f"hang time must be within 0 .. 1 (excluded) (got {self.hang_time})")
        if not (math.isfinite(self.exaggeration) and self.exaggeration > 0.0):
            raise ValueError(f"exaggeration must be finite and > 0 (got {self.exaggeration})")

    @property
    def off(self) -> bool:
        return self.hang_time == 0.0 and self.exaggeration == 1.0


def flights(times: np.ndarray, positions: np.ndarray, gravity,
            step: float = 0.0) -> list[tuple[int, int]]:
    """The flights of one body: (first, last) sample indices of each run in free fall that
    rises then falls.

    Args:
        times: (F,) increasing sample times [s]. positions: (F, 3) [m]. gravity: (3,) [m/s^2].
        step: the simulation's sub-step [s] when samples fall between sub-steps (slow motion):
            their motion is straight within a sub-step, so velocities jump by g step at its
            ends, which is free fall too.
    """
    g = np.asarray(gravity, np.float64)
    if len(times) < MIN_FLIGHT_SAMPLES or not np.any(g):
        return []
    up = -g / np.linalg.norm(g)
    dt = np.diff(times)
    v = np.diff(positions, axis=0) / dt[:, None]  # over each interval
    mid = 0.5 * (times[1:] + times[:-1])
    # free fall between intervals k and k + 1: v changes by g times the time between them
    change = np.diff(v, axis=0) - g * np.diff(mid)[:, None]
    slack = SLACK + SLACK_FRACTION * np.linalg.norm(v[1:], axis=1) \
        + float(np.linalg.norm(g)) * step
    free = np.linalg.norm(change, axis=1) <= slack
    out = []
    k = 0
    while k < len(free):
        if not free[k]:
            k += 1
            continue
        start = k
        while k < len(free) and free[k]:
            k += 1
        first, last = start, k + 1  # samples of the intervals start .. k, all in free fall
        rise = v[first:last] @ up
        if last - first + 1 >= MIN_FLIGHT_SAMPLES and rise[0] > 0.0 > rise[-1]:
            out.append((first, last))
    return out


def _tangents(t: np.ndarray, p: np.ndarray) -> np.ndarray:
    """dp/dt at each sample by the three-point formula (exact for a parabola)."""
    d = np.empty_like(p)
    if len(t) < 3:
        d[:] = (p[-1] - p[0]) / (t[-1] - t[0])
        return d
    h0, h1 = np.diff(t)[:-1, None], np.diff(t)[1:, None]
    d[1:-1] = (h0 * h0 * (p[2:] - p[1:-1]) + h1 * h1 * (p[1:-1] - p[:-2])) / (h0 * h1 * (h0 + h1))
    for end, (i0, i1, i2) in ((0, (0, 1, 2)), (-1, (-1, -2, -3))):
        a, b = t[i1] - t[i0], t[i2] - t[i0]
        d[end] = ((p[i1] - p[i0]) * b * b - (p[i2] - p[i0]) * a * a) / (a * b * (b - a))
    return d


def _hermite(t: np.ndarray, p: np.ndarray, d: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The cubic Hermite curve through (t, p) with tangents d, at times s."""
    k = np.clip(np.searchsorted(t, s, side="right") - 1, 0, len(t) - 2)
    h = (t[k + 1] - t[k])[:, None]
    x = ((s - t[k]) / (t[k + 1] - t[k]))[:, None]
    x2, x3 = x * x, x * x * x
    return ((2 * x3 - 3 * x2 + 1) * p[k] + (x3 - 2 * x2 + x) * h * d[k]
            + (-2 * x3 + 3 * x2) * p[k + 1] + (x3 - x2) * h * d[k + 1])


def eased(u: np.ndarray, apex: float, hang_time: float) -> np.ndarray:
    """Shown time -> simulated time over a flight normalised to [0, 1] with its apex at
    ``apex`` (the module docstring's s(u))."""
    u = np.asarray(u, np.float64)

    def w(x):
        return x + (hang_time / math.pi) * np.sin(math.pi * x)

    rising = apex * w(u / apex)
    falling = apex + (1.0 - apex) * (1.0 - w((1.0 - u) / (1.0 - apex)))
    return np.where(u <= apex, rising, falling)


def shape_flights(times: np.ndarray, positions: np.ndarray, rotations: np.ndarray, gravity,
                  settings: FlightSettings, keep: tuple[int, ...] = (), step: float = 0.0
                  ) -> tuple[np.ndarray, np.ndarray]:
    """One body's shown positions (F, 3) and unit quaternions (F, 4) with hang time and
    exaggeration applied to each of its flights (:func:`flights`); elsewhere unchanged, and in
    a flight holding a sample index of ``keep`` (a frame it must be on as simulated: its
    mark) too. ``step``: the simulation's sub-step, see :func:`flights`."""
    pos = np.array(positions, np.float64)
    rot = np.array(rotations, np.float64)
    if settings.off:
        return pos, rot
    g = np.asarray(gravity, np.float64)
    up = -g / np.linalg.norm(g) if np.any(g) else np.zeros(3)
    for first, last in flights(times, pos, g, step):
        if any(first < k < last for k in keep):
            continue
        t = np.asarray(times[first:last + 1], np.float64)
        p = pos[first:last + 1].copy()
        q = rot[first:last + 1].copy()
        span = t[-1] - t[0]
        height = p @ up
        line = height[0] + (height[-1] - height[0]) * (t - t[0]) / span
        p += ((settings.exaggeration - 1.0) * (height - line))[:, None] * up
        if settings.hang_time > 0.0:
            d = _tangents(t, p)
            # the apex: where the rise speed changes sign, on the Hermite curve's samples
            rise = d @ up
            k = int(np.nonzero(rise[:-1] * rise[1:] <= 0.0)[0][0])
            apex_t = t[k] + (t[k + 1] - t[k]) * rise[k] / (rise[k] - rise[k + 1])
            apex = (apex_t - t[0]) / span
            shown = t[0] + span * eased((t - t[0]) / span, apex, settings.hang_time)
            new_p = _hermite(t, p, d, shown)
            j = np.clip(np.searchsorted(t, shown, side="right") - 1, 0, len(t) - 2)
            frac = (shown - t[j]) / (t[j + 1] - t[j])
            q = slerp(q[j], q[j + 1], frac)
            new_p[[0, -1]] = p[[0, -1]]  # take-off and landing exactly as simulated
            q[[0, -1]] = rot[[first, last]]
            p = new_p
        pos[first:last + 1] = p
        rot[first:last + 1] = q
    return pos, rot
