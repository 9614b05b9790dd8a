"""Interactions among particles: Witkin & Baraff's third kind of force, the spatial one, where
each particle feels the others near it (or all of them) — mutual gravity, Lennard-Jones and
Coulomb forces.

An interaction is a frozen setting naming the emitters whose particles take part (all of them
mutually: a pair of members pulls or pushes both ways, equal and opposite, so the members'
momentum is untouched). :meth:`bind` turns it, for one sub-step, into a force on the particle
state's arrays (:class:`~.fields.ParticleView` order), which adds into the accumulator like the
field forces do. The expensive part is finding who is near whom: Lennard-Jones and Coulomb
forces are cut off at a distance and use the cell grid of :mod:`..collision.neighbours`; gravity
reaches everywhere and uses the tree code of :mod:`.barnes_hut` (the exact sum for theta 0).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..collision.neighbours import neighbour_pairs
from ..errors import PhysanimError
from . import barnes_hut
from .fields import ParticleView


MAX_EXACT_PAIRS = 200_000_000  # the exact gravity sum beyond this is minutes a step


def _check(owner: str, **values) -> None:
    for key, value in values.items():
        if not (math.isfinite(value) and value >= 0.0):
            raise ValueError(f'{owner}: {key} must be finite and >= 0 (got {value})')


def _neighbours(name: str, x: np.ndarray, cutoff: float) -> tuple[np.ndarray, np.ndarray]:
    """The member pairs within ``cutoff``; too many (particles crowded within it) is an error
    naming the force (the solver adds the frame)."""
    try:
        return neighbour_pairs(x, cutoff)
    except ValueError as exc:
        raise PhysanimError(f"{exc} — lower its Cutoff, or spread the particles",
                            obj=name, kind="force") from exc


def _members(emitters: tuple[int, ...], particle_emitter: np.ndarray) -> np.ndarray:
    """Indices of the particles of ``emitters`` (all particles when it is empty)."""
    if not emitters:
        return np.arange(len(particle_emitter))
    return np.flatnonzero(np.isin(particle_emitter, emitters))


def _scatter(f_out: np.ndarray, members: np.ndarray, i: np.ndarray, j: np.ndarray,
             force: np.ndarray) -> None:
    """f_out[members[i]] += force, f_out[members[j]] -= force (pairs, equal and opposite)."""
    n = len(members)
    total = np.zeros((n, 3))
    for k in range(3):
        total[:, k] = (np.bincount(i, force[:, k], minlength=n)
                       - np.bincount(j, force[:, k], minlength=n))
    f_out[members] += total


@dataclass(frozen=True)
class MutualGravity:
    """Members attract each other: f_i = G m_i sum_j m_j (x_j - x_i) / (r^2 + eps^2)^(3/2).

    Args:
        name: the force object's name (messages). G: gravitational constant [m^3/(kg s^2)]
        (the scene's own scale: 6.674e-11 is the real one). softening: eps [m] (> 0 keeps close
        passes finite). theta: Barnes-Hut opening angle (0: the exact sum). emitters: member
        emitters' indices (empty: all).
    """

    name: str
    G: float = 1.0
    softening: float = 0.05
    theta: float = 0.5
    emitters: tuple[int, ...] = ()

    def __post_init__(self):
        _check(f'force "{self.name}"', G=self.G, softening=self.softening, theta=self.theta)
        if self.theta > 2.0:
            raise ValueError(f'force "{self.name}": theta must be at most 2 (got {self.theta})')

    def bind(self, particle_emitter: np.ndarray) -> _BoundGravity:
        return _BoundGravity(self, _members(self.emitters, particle_emitter))

    def max_step(self, mass: float) -> float:
        """No step bound: softening keeps the pull finite."""
        return math.inf


@dataclass(frozen=True)
class _BoundGravity:
    spec: MutualGravity
    members: np.ndarray

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        if len(self.members) < 2 or self.spec.G == 0.0:
            return
        s = self.spec
        n = len(self.members)
        if (s.theta == 0.0 or n < barnes_hut.EXACT_BELOW) and n * (n - 1) // 2 > MAX_EXACT_PAIRS:
            raise PhysanimError(f"the exact sum (Opening Angle 0) over {n:,} particles is "
                                f"{n * (n - 1) // 2:,} pairs a step — raise the Opening Angle "
                                "(0.5: about 0.15 % error)", obj=s.name, kind="force")
        m = p.mass[self.members]
        try:
            a = barnes_hut.accelerations(p.x[self.members], m, s.G, s.softening, s.theta)
        except barnes_hut.TooManyInteractions as exc:
            raise PhysanimError(
                f"the Opening Angle {s.theta:g} over {n:,} particles takes about "
                f"{exc.interactions:,} interactions a step (the limit is "
                f"{barnes_hut.interaction_limit(n):,}) — raise the Opening Angle "
                "(0.5: about 0.15 % error)", obj=s.name, kind="force") from None
        f_out[self.members] += m[:, None] * a


@dataclass(frozen=True)
class LennardJones:
    """Members repel up close and attract a little farther (a liquid, a droplet). The 12-6
    potential with a soft core (Beutler's): with s = a + (r / sigma)^6,

        U(r) = 4 epsilon (1 / s^2 - 1 / s),

    which for softness a = 0 is Lennard-Jones' own 4 epsilon ((sigma / r)^12 - (sigma / r)^6),
    minimum at r* = 2^(1/6) sigma. A softness a > 0 keeps the force finite (at most about
    24 epsilon / sigma at a = 0.5) so particles meeting fast, or born on top of each other,
    bounce off instead of needing microsecond steps; the minimum moves to (2 - a)^(1/6) sigma
    and the core's height to 4 epsilon (1 / a^2 - 1 / a). Cut off at ``cutoff`` (shifted to 0
    there, so the potential is continuous).

    Args:
        name: the force object's name. sigma: [m]. epsilon: well depth [J]. cutoff: [m]
        (> sigma; 2.5 sigma is the usual choice). softness: a (0: the hard 12-6 core, which
        needs steps short against sigma over the particles' speed). emitters: member emitters
        (empty: all).
    """

    name: str
    sigma: float = 0.1
    epsilon: float = 0.002
    cutoff: float = 0.25
    softness: float = 0.5
    emitters: tuple[int, ...] = ()

    def __post_init__(self):
        _check(f'force "{self.name}"', sigma=self.sigma, epsilon=self.epsilon,
               cutoff=self.cutoff, softness=self.softness)
        if self.sigma <= 0.0 or self.cutoff <= self.sigma:
            raise ValueError(f'force "{self.name}": Lennard-Jones needs sigma > 0 and a cutoff '
                             f"beyond it (got sigma {self.sigma:g} m, cutoff {self.cutoff:g} m)")
        if self.softness >= 2.0:
            raise ValueError(f'force "{self.name}": softness must be below 2 (got '
                             f"{self.softness:g}): at 2 the potential has no well")

    @property
    def minimum(self) -> float:
        """r* [m], where the force turns from push to pull."""
        return self.sigma * (2.0 - self.softness) ** (1.0 / 6.0)

    def bind(self, particle_emitter: np.ndarray) -> _BoundLennardJones:
        return _BoundLennardJones(self, _members(self.emitters, particle_emitter))

    def max_step(self, mass: float) -> float:
        """The longest explicit step [s] for particles of ``mass`` [kg] packed in a drop:
        1 / omega with omega^2 = 24 U''(r*) / m (twelve neighbours, each bond's curvature at
        the minimum; symplectic Euler needs omega h < 2, this keeps half that)."""
        r, h = self.minimum, 1e-4 * self.sigma
        curvature = float((self.energy(r + h) - 2.0 * self.energy(r) + self.energy(r - h))
                          / (h * h))
        return math.sqrt(mass / (24.0 * max(curvature, 1e-300)))

    def energy(self, r: np.ndarray) -> np.ndarray:
        """U(r) [J], shifted to 0 at the cutoff and 0 beyond it."""
        def u(d):
            s = self.softness + (d / self.sigma) ** 6
            return 4.0 * self.epsilon * (1.0 / (s * s) - 1.0 / s)
        r = np.asarray(r, np.float64)
        return np.where(r < self.cutoff, u(r) - u(self.cutoff), 0.0)


@dataclass(frozen=True)
class _BoundLennardJones:
    spec: LennardJones
    members: np.ndarray

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        if len(self.members) < 2:
            return
        s = self.spec
        x = p.x[self.members]
        i, j = _neighbours(s.name, x, s.cutoff)
        d = x[i] - x[j]
        r2 = np.einsum("ij,ij->i", d, d)
        if s.softness == 0.0:  # a pair at one place has no direction: pushed along no axis
            r2 = np.maximum(r2, (1e-3 * s.sigma) ** 2)
        # f on i = -dU/dr d / r = 24 eps (2 / s^3 - 1 / s^2) r^4 / sigma^6 d
        q = r2 * r2 * r2 / s.sigma ** 6
        inv = 1.0 / (s.softness + q)
        w = 24.0 * s.epsilon * (2.0 * inv - 1.0) * inv * inv * r2 * r2 / s.sigma ** 6
        _scatter(f_out, self.members, i, j, d * w[:, None])


@dataclass(frozen=True)
class Coulomb:
    """Charged members push (like charges) or pull (unlike) each other:
    f_i = k q_i q_j (x_i - x_j) / (r^2 + eps^2)^(3/2), up to ``cutoff``.

    Args:
        name: the force object's name. k: Coulomb constant [N m^2 / C^2] (the scene's own
        scale: 8.988e9 is the real one). cutoff: [m]. softening: eps [m]. charges: each
        emitter's charge per particle [C], by emitter index (missing: 0). emitters: member
        emitters (empty: all).
    """

    name: str
    k: float = 1.0
    cutoff: float = 1.0
    softening: float = 0.01
    charges: tuple[float, ...] = ()
    emitters: tuple[int, ...] = ()

    def __post_init__(self):
        _check(f'force "{self.name}"', k=self.k, cutoff=self.cutoff, softening=self.softening)
        if self.cutoff <= 0.0:
            raise ValueError(f'force "{self.name}": cutoff must be > 0 (got {self.cutoff})')
        if not all(math.isfinite(q) for q in self.charges):
            raise ValueError(f'force "{self.name}": charges must be finite (got '
                             f"{self.charges})")

    def max_step(self, mass: float) -> float:
        """No step bound: softening keeps the push finite."""
        return math.inf

    def bind(self, particle_emitter: np.ndarray) -> _BoundCoulomb:
        members = _members(self.emitters, particle_emitter)
        table = np.zeros(int(particle_emitter.max()) + 1 if len(particle_emitter) else 0)
        count = min(len(table), len(self.charges))
        table[:count] = self.charges[:count]
        charge = table[particle_emitter[members]] if len(members) else np.zeros(0)
        keep = charge != 0.0
        return _BoundCoulomb(self, members[keep], charge[keep])


@dataclass(frozen=True)
class _BoundCoulomb:
    spec: Coulomb
    members: np.ndarray
    charge: np.ndarray

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        if len(self.members) < 2 or self.spec.k == 0.0:
            return
        s = self.spec
        x = p.x[self.members]
        i, j = _neighbours(s.name, x, s.cutoff)
        d = x[i] - x[j]
        r2 = np.einsum("ij,ij->i", d, d) + s.softening * s.softening
        with np.errstate(divide="ignore"):  # two charges at one place push along no axis
            w = np.where(r2 > 0.0, s.k * self.charge[i] * self.charge[j] / (r2 * np.sqrt(r2)),
                         0.0)
        _scatter(f_out, self.members, i, j, d * w[:, None])


INTERACTIONS = (MutualGravity, LennardJones, Coulomb)
