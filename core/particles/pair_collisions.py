"""Particles colliding with each other as spheres of their size: restitution, friction, resting
piles, momentum conserved exactly, and no pair passing through another within a sub-step.

After a sub-step has moved every particle (forces, colliders), the pairs that can touch during
it are found on the cell grid (their spheres within reach of each other once the sub-step's
motion is allowed for) and resolved as speculative contacts with sequential impulses, a few
Jacobi passes (Box2D's way, for spheres):

    contact   along the pair's normal n at the sub-step's start, the relative velocity may close
              at most the gap between the spheres over the step: (v_i - v_j) . n >= -gap / h.
              A pair that meets no faster than that never touches, and never passes through
              however fast it flies (the gap is closed exactly, not crossed)
    bounce    a pair that meets faster than the rest speed leaves at restitution times its
              approach speed along n
    friction  the sliding velocity in the contact plane is taken back, up to mu times the
              normal impulse (all of it within that: static friction)
    momentum  every impulse acts on both, equal and opposite, shared in inverse proportion to
              their masses: a pair's and the system's momentum are kept exactly

The velocity changes act over the whole sub-step (x += h dv), then whatever overlap is left
(particles born inside each other, a heap pressing down) is pushed apart in position only,
without giving anyone speed. A particle in several contacts takes each pair's impulse scaled by
1 / (the larger contact count of the pair): the Jacobi passes stay stable in a heap.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..collision.neighbours import neighbour_pairs
from ..errors import PhysanimError

POSITION_PASSES = 3  # position passes per velocity pass (they stop once the overlap is left)
TOLERANCE = 0.002  # of the sum of radii: overlap the position passes leave (0.4 % of a radius)
RELAX = 1.5  # over-relaxation of the position passes (a particle's mean push, times this)


@dataclass(frozen=True)
class ParticleCollisions:
    """Collisions among the particles of ``emitters`` (empty: all), each a sphere of its size.

    Args:
        name: the force object's name (messages). restitution: 0 .. 1 of the approach speed
        kept along the normal. friction: Coulomb's mu between particles. iterations: Jacobi
        passes per sub-step (more: stiffer heaps). emitters: member emitters' indices.
    """

    name: str
    restitution: float = 0.3
    friction: float = 0.5
    iterations: int = 8
    emitters: tuple[int, ...] = ()

    def __post_init__(self):
        owner = f'force "{self.name}"'
        if not (math.isfinite(self.restitution) and 0.0 <= self.restitution <= 1.0):
            raise ValueError(f"{owner}: restitution must be within 0 .. 1 (got "
                             f"{self.restitution})")
        if not (math.isfinite(self.friction) and self.friction >= 0.0):
            raise ValueError(f"{owner}: friction must be finite and >= 0 (got {self.friction})")
        if not (isinstance(self.iterations, int) and 1 <= self.iterations <= 100):
            raise ValueError(f"{owner}: iterations must be an integer within 1 .. 100 (got "
                             f"{self.iterations})")

    def max_step(self, mass: float) -> float:
        """No step bound: the passes are position-based (unconditionally stable)."""
        return math.inf

    def resolve(self, x: np.ndarray, v: np.ndarray, x0: np.ndarray, v0: np.ndarray,
                radius: np.ndarray, mass: np.ndarray, emitter: np.ndarray, h: float,
                rest_speed: float, support: tuple[np.ndarray, np.ndarray] | None = None,
                ids: np.ndarray | None = None, warm: tuple | None = None
                ) -> tuple[np.ndarray, np.ndarray, int, tuple]:
        """The sub-step's particle-particle collisions.

        Args:
            x, v: (n, 3) positions and velocities at the sub-step's end (after colliders).
            x0, v0: (n, 3) at its start. radius, mass: (n,). emitter: (n,) emitter indices.
            h: the sub-step [s]. rest_speed: approach speeds below it do not bounce [m/s].
            support: (indices, normals (k, 3)) of the particles resting on a collider: a
                neighbour cannot push them into it (the collider takes that push, as the
                ground holds up a heap).
            ids: (n,) the particles' unique ids; warm: the last sub-step's (pair keys,
                normal impulses), returned by it: pairs still in contact start from the
                impulse they had (a heap holds its weight from the first pass).

        Returns:
            New (x, v), the number of pairs that touched and the warm start for the next
            sub-step.
        """
        members = (np.arange(len(x)) if not self.emitters
                   else np.flatnonzero(np.isin(emitter, self.emitters)))
        none = (np.zeros(0, np.int64), np.zeros(0))
        if len(members) < 2:
            return x, v, 0, none
        xm, x0m, vm = x[members], x0[members], v[members].copy()
        held, floor = _supported(members, support, len(x))
        r, w = radius[members], 1.0 / mass[members]
        moved = np.linalg.norm(xm - x0m, axis=1)
        try:
            i, j = neighbour_pairs(x0m, max(2.0 * float(r.max()) + 2.0 * float(moved.max()),
                                            1e-9))
        except ValueError as exc:  # crowded: every particle within reach of every other
            raise PhysanimError(f"{exc} — the particles are crowded or fly too far in a "
                                "sub-step: raise Substeps, or lower the rate", obj=self.name,
                                kind="force") from exc
        d0 = x0m[i] - x0m[j]
        dist = np.linalg.norm(d0, axis=1)
        reach = r[i] + r[j]
        gap = dist - reach
        # pairs that can meet this sub-step: those whose closing motion covers their gap
        normal = np.where(dist[:, None] > 1e-12, d0 / np.maximum(dist, 1e-300)[:, None],
                          np.array([0.0, 0.0, 1.0]))  # two centres at one place: any axis
        closing = -np.einsum("ij,ij->i", (xm[i] - x0m[i]) - (xm[j] - x0m[j]), normal)
        near = gap <= np.maximum(closing, 0.0) + 1e-9
        candidates = (i, j, reach)  # the position passes look at all: pushes move others
        i, j, normal, gap, reach = i[near], j[near], normal[near], gap[near], reach[near]
        if not len(i):
            new = _apart(xm.copy(), w, *candidates, held, floor, xm,
                         POSITION_PASSES * self.iterations)
            x = x.copy()
            x[members] = new
            return x, v, 0, none
        share = w[i] / (w[i] + w[j])  # of a pair's impulse that i takes (j: the rest)
        count = np.bincount(np.concatenate([i, j]), minlength=len(members))
        scale = 1.0 / np.maximum(count[i], count[j])
        approach = np.einsum("ij,ij->i", v0[members][i] - v0[members][j], normal)
        meets = approach * h < -np.maximum(gap, 0.0)  # it would touch within the step
        bounce = meets & (approach < -rest_speed)
        lower = np.where(bounce, -self.restitution * approach,
                         -np.maximum(gap, 0.0) / h)  # the least relative normal velocity
        start_v = vm.copy()
        keys = _pair_keys(ids, members, i, j)
        taken = _warm(keys, warm)  # accumulated normal impulse (as a relative velocity)
        _move(vm, i, j, normal * taken[:, None], share)
        _hold(vm, held, floor, vm)
        rubbed = np.zeros((len(i), 3))  # the friction impulse so far (a relative velocity)
        for _ in range(self.iterations):
            rel = np.einsum("ij,ij->i", vm[i] - vm[j], normal)
            step = np.maximum(taken + (lower - rel) * scale, 0.0) - taken
            taken += step
            _move(vm, i, j, normal * step[:, None], share)
            # friction: the sliding velocity taken back, the pair's friction impulse over all
            # passes at most mu times its normal impulse (Coulomb's cone)
            slide = vm[i] - vm[j]
            slide -= np.einsum("ij,ij->i", slide, normal)[:, None] * normal
            total = rubbed - slide * scale[:, None]
            length = np.linalg.norm(total, axis=1)
            limit = self.friction * taken
            total *= np.minimum(1.0, limit / np.where(length > 0.0, length, 1.0))[:, None]
            _move(vm, i, j, total - rubbed, share)
            rubbed = total
            _hold(vm, held, floor, vm)
        new = xm + h * (vm - start_v)
        new = _apart(new, w, *candidates, held, floor, xm, POSITION_PASSES * self.iterations)
        x, v = x.copy(), v.copy()
        x[members], v[members] = new, vm
        touching = taken > 0.0
        return x, v, int(touching.sum()), (keys[touching], taken[touching])

def _apart(x: np.ndarray, w: np.ndarray, i: np.ndarray, j: np.ndarray, reach: np.ndarray,
           held: np.ndarray, floor: np.ndarray, origin: np.ndarray, passes: int) -> np.ndarray:
    """Overlap left (born inside each other, a heap pressing down) pushed apart in position
    only (no one gains speed, momentum untouched): each pass, every overlapping pair along its
    current line, each particle taking the mean of its pushes, over-relaxed; a particle on a
    collider is not pushed into it."""
    share = w[i] / (w[i] + w[j])
    for _ in range(passes):
        d = x[i] - x[j]
        dist = np.linalg.norm(d, axis=1)
        depth = reach - dist
        over = depth > TOLERANCE * reach
        if not over.any():
            break
        a, b, depth, d, dist = i[over], j[over], depth[over], d[over], dist[over]
        normal = np.where(dist[:, None] > 1e-12, d / np.maximum(dist, 1e-300)[:, None],
                          np.array([0.0, 0.0, 1.0]))  # two centres at one place: any axis
        count = np.maximum(np.bincount(np.concatenate([a, b]), minlength=len(x)), 1)
        before = x.copy()
        _move(x, a, b, normal * depth[:, None], share[over])
        x = before + RELAX * (x - before) / count[:, None]
        _hold(x - origin, held, floor, x)
    return x


def _pair_keys(ids, members: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """A key per pair from its two particles' ids (the same pair, the same key)."""
    if ids is None:
        return np.zeros(len(i), np.int64)
    a, b = ids[members[i]], ids[members[j]]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    return lo * np.int64(1 << 31) + hi


def _warm(keys: np.ndarray, warm) -> np.ndarray:
    """The last sub-step's normal impulse of each pair still in contact (0 for new pairs)."""
    out = np.zeros(len(keys))
    if warm is None or not len(warm[0]) or not len(keys):
        return out
    old_keys, old_impulse = warm
    order = np.argsort(old_keys)
    at = np.minimum(np.searchsorted(old_keys[order], keys), len(order) - 1)
    hit = old_keys[order][at] == keys
    out[hit] = old_impulse[order][at[hit]]
    return out


def _supported(members: np.ndarray, support, n: int):
    """Which members rest on a collider (indices into members) and its normal there."""
    if support is None or not len(support[0]):
        return np.zeros(0, np.int64), np.zeros((0, 3))
    where = np.full(n, -1, np.int64)
    where[members] = np.arange(len(members))
    k = where[support[0]]
    keep = k >= 0
    return k[keep], np.asarray(support[1])[keep]


def _hold(change: np.ndarray, held: np.ndarray, floor: np.ndarray, out: np.ndarray) -> None:
    """Where ``change`` (a velocity, or a move) of a supported particle points into its
    collider, take that part out of ``out``: the collider pushes back."""
    if not len(held):
        return
    into = np.einsum("ij,ij->i", change[held], floor)
    out[held] -= np.minimum(into, 0.0)[:, None] * floor


def _move(a: np.ndarray, i: np.ndarray, j: np.ndarray, amount: np.ndarray,
          share: np.ndarray) -> None:
    """a[i] += share * amount, a[j] -= (1 - share) * amount, summed over pairs: mass-weighted,
    so the pair's momentum (or centre of mass) is unchanged."""
    n = len(a)
    for k in range(3):
        a[:, k] += (np.bincount(i, amount[:, k] * share, minlength=n)
                    - np.bincount(j, amount[:, k] * (1.0 - share), minlength=n))
