"""Squash and stretch (Lasseter): a shape that stretches along its velocity in flight and squashes
along the contact normal on impact, recovering over a time, its volume kept — drawn on top of a
simulation that stays rigid (contacts and paths are the simulation's own).

The deformation is S = exp(L) with the symmetric, trace-free

    L = ln(a) (v v^T - (I - v v^T) / 2) + ln(b) (n n^T - (I - n n^T) / 2)

(v, n unit vectors): stretching by a along v and by 1/sqrt(a) across it, squashing by b along n
and by 1/sqrt(b) across it. trace L = 0, so det S = 1 exactly: the volume is kept. With
ln a = amount * STRETCH * |v| and ln b = -amount * SQUASH * u * exp(-age / recovery) for an
impact of speed change u that happened ``age`` seconds ago.

Impacts are read from the motion itself (:class:`ImpactTracker`): between two samples the
velocity changes by g dt in free flight; a change beyond that by more than a threshold is an
impact, along the direction of the change (the contact's normal impulse, for a bounce).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: ln of the stretch per unit speed [s/m] at amount 1: 10 m/s stretches by e^0.2 = 1.22.
STRETCH = 0.02
#: ln of the squash per unit impact speed [s/m] at amount 1: a 10 m/s bounce squashes to e^-0.5.
SQUASH = 0.05


@dataclass(frozen=True)
class SquashSettings:
    """Attributes:
        amount: 0 (off) .. (1: the STRETCH and SQUASH scales above).
        recovery: seconds for an impact's squash to fall to 1/e (> 0).
        threshold: speed change beyond free flight that counts as an impact [m/s].
    """

    amount: float = 1.0
    recovery: float = 0.15
    threshold: float = 0.5

    def __post_init__(self):
        for name, value, low in (("amount", self.amount, 0.0), ("threshold", self.threshold, 0.0)):
            if not (math.isfinite(value) and value >= low):
                raise ValueError(f"squash and stretch {name} must be finite and >= {low} "
                                 f"(got {value})")
        if not (math.isfinite(self.recovery) and self.recovery > 0.0):
            raise ValueError(f"squash and stretch recovery must be finite and > 0 s (got "
                             f"{self.recovery})")


def _unit(x: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(x, axis=-1, keepdims=True)
    return np.divide(x, norm, out=np.zeros_like(x), where=norm > 1e-12)


def _axis_term(direction: np.ndarray, log_scale: np.ndarray) -> np.ndarray:
    """ln(s) (d d^T - (I - d d^T) / 2) for unit d (n, 3) and ln s (n,): (n, 3, 3)."""
    outer = direction[:, :, None] * direction[:, None, :]
    return log_scale[:, None, None] * (1.5 * outer - 0.5 * np.eye(3))


def log_deformation(velocity: np.ndarray, impact: np.ndarray, impact_age: np.ndarray,
                    settings: SquashSettings) -> np.ndarray:
    """L (n, 3, 3) for velocities (n, 3) [m/s], the last impacts (n, 3) (normal times speed
    change [m/s]; zero: none yet) and their ages (n,) [s]."""
    speed = np.linalg.norm(velocity, axis=1)
    stretch = settings.amount * STRETCH * speed
    strength = np.linalg.norm(impact, axis=1)
    squash = -settings.amount * SQUASH * strength * np.exp(-np.maximum(impact_age, 0.0)
                                                            / settings.recovery)
    return _axis_term(_unit(velocity), stretch) + _axis_term(_unit(impact), squash)


def principal(log_matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rotation (n, 3, 3), scale (n, 3)) with exp(L) = R diag(scale) R^T, det R = +1: the axes
    and factors of the deformation. The factors' product is 1 (to rounding)."""
    values, vectors = np.linalg.eigh(log_matrix)
    flip = np.linalg.det(vectors) < 0.0
    vectors[flip, :, 2] *= -1.0
    return vectors, np.exp(values - values.sum(axis=1, keepdims=True) / 3.0)


def euler_xyz(rotation: np.ndarray) -> np.ndarray:
    """XYZ Euler angles (n, 3) [rad] of rotation matrices (n, 3, 3) (R = Rz Ry Rx)."""
    r = rotation
    y = np.arcsin(np.clip(-r[:, 2, 0], -1.0, 1.0))
    x = np.arctan2(r[:, 2, 1], r[:, 2, 2])
    z = np.arctan2(r[:, 1, 0], r[:, 0, 0])
    return np.stack([x, y, z], axis=1)


class ImpactTracker:
    """The last impact of each of a set of bodies or particles, from their velocities sample by
    sample.

    Args:
        settings: the threshold. gravity: (3,) [m/s^2], the free-flight velocity change.
    """

    def __init__(self, settings: SquashSettings, gravity):
        self.settings = settings
        self.gravity = np.asarray(gravity, np.float64)
        self.ids = np.zeros(0, np.int64)
        self.velocity = np.zeros((0, 3))
        self.impact = np.zeros((0, 3))
        self.age = np.zeros(0)

    def update(self, ids: np.ndarray, velocity: np.ndarray, dt: float) -> tuple[np.ndarray,
                                                                                 np.ndarray]:
        """Advance by ``dt`` [s] to the sample of ``ids`` (n,) (any order, each unique) with
        ``velocity`` (n, 3); returns their (impact (n, 3), age (n,)). An id not seen before
        starts with no impact."""
        ids = np.asarray(ids, np.int64)
        velocity = np.asarray(velocity, np.float64)
        impact = np.zeros((len(ids), 3))
        age = np.full(len(ids), np.inf)
        order = np.argsort(self.ids)
        where = np.searchsorted(self.ids, ids, sorter=order)
        where = np.minimum(where, max(len(self.ids) - 1, 0))
        known = (len(self.ids) > 0) & (self.ids[order[where]] == ids) if len(self.ids) else \
            np.zeros(len(ids), bool)
        slot = order[where[known]]
        impact[known] = self.impact[slot]
        age[known] = self.age[slot] + dt
        change = velocity[known] - self.velocity[slot] - self.gravity * dt
        hit = np.linalg.norm(change, axis=1) > self.settings.threshold
        rows = np.nonzero(known)[0][hit]
        impact[rows] = change[hit]
        age[rows] = 0.0
        self.ids, self.velocity, self.impact, self.age = ids.copy(), velocity.copy(), impact, age
        return impact, age
