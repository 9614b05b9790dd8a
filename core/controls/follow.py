"""Follow-through: a point that trails a moving target through a damped spring — the secondary
motion of an antenna, a pony tail or a hat on a character (Lasseter's follow-through and
overlapping action).

The point c follows the target p as a mass on a spring of natural frequency w and damping ratio
z, the damping acting on the velocity relative to the target (steady motion leaves no lag):

    c'' = -w^2 (c - p) - 2 z w (c' - p')

With the offset e = c - p and the target moving linearly between samples (p'' = 0 there), e
obeys e'' + 2 z w e' + w^2 e = 0 inside each interval and is advanced exactly by the matrix
exponential of that 2 x 2 system (:func:`transition`); where the target's velocity changes, at a
sample, c' is continuous, so e' jumps by minus the change. The result is exact for a piecewise
linear target, whatever the sample spacing — no step size to choose, no instability at any
stiffness.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FollowSettings:
    """A follower's spring.

    Attributes:
        frequency: natural frequency of the spring [Hz] (> 0): higher follows more tightly.
        damping: damping ratio (>= 0): 0 swings forever, 1 settles fastest without overshoot.
    """

    frequency: float = 2.0
    damping: float = 0.3

    def __post_init__(self):
        if not (math.isfinite(self.frequency) and self.frequency > 0.0):
            raise ValueError(f"follow-through frequency must be finite and > 0 Hz (got "
                             f"{self.frequency})")
        if not (math.isfinite(self.damping) and self.damping >= 0.0):
            raise ValueError(f"follow-through damping ratio must be finite and >= 0 (got "
                             f"{self.damping})")


def transition(settings: FollowSettings, h: float) -> np.ndarray:
    """The 2 x 2 matrix taking (e, e') over ``h`` seconds of e'' + 2 z w e' + w^2 e = 0.

    exp(A h) = exp(tau h / 2) [c(h) I + s(h) (A - tau / 2 I)], tau = trace A = -2 z w, with
    c, s = cosh(q h), sinh(q h) / q for q^2 = w^2 (z^2 - 1) > 0, cos(q h), sin(q h) / q for
    q^2 = -w^2 (1 - z^2) < 0 (q its magnitude), and 1, h at critical damping.
    """
    w = 2.0 * math.pi * settings.frequency
    z = settings.damping
    a = np.array([[0.0, 1.0], [-w * w, -2.0 * z * w]])
    half = -z * w
    q2 = w * w * (z * z - 1.0)
    if q2 > 1e-12 * w * w:
        q = math.sqrt(q2)
        c, s = math.cosh(q * h), math.sinh(q * h) / q
    elif q2 < -1e-12 * w * w:
        q = math.sqrt(-q2)
        c, s = math.cos(q * h), math.sin(q * h) / q
    else:
        c, s = 1.0, h
    return math.exp(half * h) * (c * np.eye(2) + s * (a - half * np.eye(2)))


def follow_through(times: np.ndarray, target: np.ndarray, settings: FollowSettings,
                   start_offset: np.ndarray | None = None) -> np.ndarray:
    """Positions of a follower of ``target`` at ``times``.

    Args:
        times: (F,) increasing sample times [s].
        target: (F, ..., 3) target positions [m] at those times (linear in between): one
            follower per target, e.g. (F, N, 3) for N of them.
        settings: the spring.
        start_offset: (..., 3) offset c - p at the first sample (default 0: on the target;
            either way it starts moving with the target).

    Returns:
        (F, ..., 3) follower positions [m].

    Raises:
        ValueError: times not increasing, shapes that do not match, non-finite values.
    """
    t = np.asarray(times, np.float64)
    p = np.asarray(target, np.float64)
    if t.ndim != 1 or p.ndim < 2 or p.shape[0] != len(t) or p.shape[-1] != 3:
        raise ValueError(f"follow-through needs (F,) times and (F, ..., 3) targets (got "
                         f"{t.shape} and {p.shape})")
    if not (np.isfinite(t).all() and np.isfinite(p).all()):
        raise ValueError("follow-through: a time or a target position is not finite")
    if len(t) > 1 and not (np.diff(t) > 0.0).all():
        raise ValueError("follow-through: sample times must increase")
    out = p.copy()
    if len(t) < 2:
        return out
    h = np.diff(t)
    velocity = np.diff(p, axis=0) / h.reshape((-1,) + (1,) * (p.ndim - 1))  # per interval
    e = np.zeros(p.shape[1:])
    if start_offset is not None:
        e += np.asarray(start_offset, np.float64)
    de = np.zeros(p.shape[1:])  # relative velocity: it starts moving with the target
    cache: dict[float, np.ndarray] = {}
    previous = velocity[0]
    out[0] = p[0] + e
    for k in range(len(h)):
        de -= velocity[k] - previous  # c' is continuous where p' changes
        previous = velocity[k]
        step = cache.get(h[k])
        if step is None:
            step = cache[h[k]] = transition(settings, float(h[k]))
        e, de = step[0, 0] * e + step[0, 1] * de, step[1, 0] * e + step[1, 1] * de
        out[k + 1] = p[k + 1] + e
    return out
