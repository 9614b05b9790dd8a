"""Force objects. Each adds into a force accumulator: ``force.apply(p, f_out)``.

``p`` is a :class:`ParticleView` of point masses at one derivative evaluation (positions,
velocities, masses, time) — a particle system's particles or a spring mesh's vertices alike;
``f_out`` is (n, 3) [N]. A system's derivative is "clear the accumulator, call apply on every
force in the list, return [v, f/m]" (Witkin & Baraff). The field forces here (gravity, drag, wind,
attractor, vortex) depend only on each point's own state, so they act on any point set.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from ..transforms import cross, scale_rows
from ..validate import finite, non_negative


@dataclass
class ParticleView:
    """Particles at one evaluation: x (n, 3) [m], v (n, 3) [m/s], mass (n,) [kg], t [s]."""

    x: np.ndarray
    v: np.ndarray
    mass: np.ndarray
    t: float


class Force(Protocol):
    def apply(self, p: ParticleView, f_out: np.ndarray) -> None: ...


@dataclass(frozen=True)
class Gravity:
    """f = m g. Args: g: (3,) acceleration [m/s^2]."""

    g: tuple[float, float, float]

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        f_out += self.force(p)

    def force(self, p: ParticleView) -> np.ndarray:
        """(n, 3) m g: a new array (an accumulator can start as it). Column by column: numpy
        broadcasts an (n, 1) by (3,) product 3 x slower, row by row."""
        out = np.empty((len(p.mass), 3))
        for k, g in enumerate(self.g):
            np.multiply(p.mass, g, out=out[:, k])
        return out

    def acceleration(self, n: int, out: np.ndarray | None = None) -> np.ndarray:
        """(n, 3) g, the acceleration of a point that gravity alone pulls (into ``out``), by
        columns as :meth:`force`."""
        out = np.empty((n, 3)) if out is None else out
        for k, g in enumerate(self.g):
            out[:, k] = g
        return out


@dataclass(frozen=True)
class Drag:
    """Air drag f = -(k1 + k2 |v - w|)(v - w), w the still air's velocity (0).

    Args: name: object name. linear: k1 [kg/s]. quadratic: k2 [kg/m].
    """

    name: str
    linear: float
    quadratic: float = 0.0

    def __post_init__(self):
        non_negative(f'force "{self.name}"', linear=self.linear, quadratic=self.quadratic)

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        if self.quadratic:  # by columns (numpy runs an (n, 1) x (n, 3) broadcast row by row)
            f_out -= scale_rows(p.v, self.linear + self.quadratic * np.linalg.norm(p.v, axis=1))
        else:
            f_out -= self.linear * p.v


@dataclass(frozen=True)
class Wind:
    """A uniform push along ``direction`` with optional smooth gusts.

    f = strength * (d + noise * N(x, t)), where N is a smooth, divergent-looking vector field with
    components in about [-1, 1]: a sum of random plane waves of wavelength ``noise_scale`` [m]
    drifting with the wind at ``noise_speed`` [1/s] gust frequency. Deterministic per ``seed``.

    Args: name, direction (3,) (normalised here), strength [N], noise [-], noise_scale [m],
    noise_speed [Hz], seed.
    """

    name: str
    direction: tuple[float, float, float]
    strength: float
    noise: float = 0.0
    noise_scale: float = 1.0
    noise_speed: float = 1.0
    seed: int = 0
    _waves: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        owner = f'force "{self.name}"'
        finite(owner, strength=self.strength)
        non_negative(owner, noise=self.noise, noise_speed=self.noise_speed)
        if not (self.noise_scale > 0.0 and math.isfinite(self.noise_scale)):
            raise ValueError(f"{owner}: noise_scale must be > 0 (got {self.noise_scale})")
        d = np.asarray(self.direction, dtype=np.float64)
        n = np.linalg.norm(d)
        if not (n > 0.0 and np.isfinite(n)):
            raise ValueError(f"{owner}: direction must be a non-zero vector (got {self.direction})")
        object.__setattr__(self, "direction", tuple(d / n))
        rng = np.random.default_rng([int(self.seed) & 0xFFFFFFFF, 0x5EED])
        count = 6
        k = rng.normal(size=(count, 3, 3))  # wave vectors per (wave, output component)
        k /= np.linalg.norm(k, axis=2, keepdims=True)
        k *= 2.0 * np.pi / self.noise_scale
        phase = rng.uniform(0.0, 2.0 * np.pi, size=(count, 3))
        omega = 2.0 * np.pi * self.noise_speed * rng.uniform(0.5, 1.5, size=(count, 3))
        object.__setattr__(self, "_waves", (k, phase, omega, np.sqrt(2.0 / count)))

    def field(self, x: np.ndarray, t: float) -> np.ndarray:
        """The gust field N(x, t): (n, 3), zero mean, unit variance per component."""
        k, phase, omega, amp = self._waves
        arg = np.einsum("nd,wcd->nwc", x, k) + (phase + omega * t)
        return amp * np.sin(arg).sum(axis=1)

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        push = np.asarray(self.direction) * self.strength
        if self.noise and len(p.x):
            f_out += push + (self.strength * self.noise) * self.field(p.x, p.t)
        else:
            f_out += push


@dataclass(frozen=True)
class Attractor:
    """Pull towards (strength > 0) or push from (< 0) a point, falling off with distance.

    f = strength * r / max(d, min_distance)^(falloff + 1), r the vector to the centre and d its
    length: the falloff law strength / d^falloff outside ``min_distance``, ramping linearly to
    zero at the centre inside it (bounded everywhere). No force beyond ``max_distance``
    (0 = unlimited).
    """

    name: str
    center: tuple[float, float, float]
    strength: float
    falloff: float = 2.0
    min_distance: float = 0.1
    max_distance: float = 0.0

    def __post_init__(self):
        owner = f'force "{self.name}"'
        finite(owner, strength=self.strength)
        non_negative(owner, falloff=self.falloff, max_distance=self.max_distance)
        if not (self.min_distance > 0.0 and math.isfinite(self.min_distance)):
            raise ValueError(f"{owner}: min_distance must be > 0 (got {self.min_distance})")

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        r = np.asarray(self.center) - p.x
        d = np.linalg.norm(r, axis=1)
        dc = np.maximum(d, self.min_distance)
        mag = self.strength / dc ** (self.falloff + 1.0)  # extra power normalises r
        if self.max_distance > 0.0:
            mag = np.where(d <= self.max_distance, mag, 0.0)
        f_out += mag[:, None] * r


@dataclass(frozen=True)
class Vortex:
    """Swirl around an axis through ``center``: f = strength * (a x r_perp)/|r_perp|."""

    name: str
    center: tuple[float, float, float]
    axis: tuple[float, float, float]
    strength: float

    def __post_init__(self):
        owner = f'force "{self.name}"'
        finite(owner, strength=self.strength)
        a = np.asarray(self.axis, dtype=np.float64)
        n = np.linalg.norm(a)
        if not (n > 0.0 and np.isfinite(n)):
            raise ValueError(f"{owner}: axis must be a non-zero vector (got {self.axis})")
        object.__setattr__(self, "axis", tuple(a / n))

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        a = np.asarray(self.axis)
        r = p.x - np.asarray(self.center)
        tangent = cross(a, r)
        n = np.linalg.norm(tangent, axis=1)
        f_out += (self.strength / np.where(n > 1e-9, n, np.inf))[:, None] * tangent
