"""Particles colliding with each other as spheres of their size: restitution, friction, resting
piles, momentum conserved exactly, and no pair passing through another within a sub-step.

After a sub-step has moved every particle (forces, colliders), the pairs that can touch during
it are found by the library's uniform grid on the boxes of their sweeps, and resolved as
speculative contacts by sequential impulses, as Box2D does for bodies:

    contact   along the pair's normal n at the sub-step's start, the relative velocity may close
              at most the gap between the spheres over the step: (v_i - v_j) . n >= -gap / h.
              A pair that meets no faster than that never touches, and never passes through
              however fast it flies (the gap is closed exactly, not crossed)
    overlap   what the sub-step leaves overlapping (born inside each other, a heap pressing
              down) is pushed apart in position only (split impulses: no one keeps speed
              from an overlap, particles born inside each other drift apart), with friction
              on the pushes as on impulses (Macklin et al. 2014), so a push cannot make a heap
              flow. Under gravity the pushes favour the lower particle of a pair as if it
              were heavier, by e^(STACK x its depth below the other in radii) (Macklin et
              al.'s mass scaling for stacks): a heap's overlap goes up and out of it in a few
              passes instead of spreading through it, so a tall heap rests without sinking
              into itself
    bounce    a pair that meets faster than the rest speed leaves at restitution times its
              approach speed along n
    friction  the sliding velocity in the contact plane is taken back, up to mu times the
              normal impulse (all of it within that: static friction)
    momentum  every impulse acts on both, equal and opposite, shared in inverse proportion to
              their masses: a pair's and the system's momentum are kept exactly (a particle on
              a collider that a pair presses into it moves only along it: the collider takes
              that part, and its friction holds the foot of a heap)

The passes are Gauss-Seidel over groups of pairs that share no particle (graph colouring; each
group one vectorised step), sweeping the groups forwards then backwards, warm-started from the
impulses the pairs had a sub-step before (a heap holds its weight from the first pass and does
not creep).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..collision.broadphase_grid import TooManyCandidates, UniformGrid
from ..colouring import colour
from ..errors import PhysanimError
from ..transforms import dot_rows, norm_rows

SLACK = 0.02  # pairs within (1 + SLACK) x their reach (after the sub-step's motion) take part
SLOP = 0.0025  # of the sum of radii: the overlap resting pairs keep (0.5 % of a radius), so
#               their contact, and its warm start, lasts from one sub-step to the next
STACK = 0.5  # per radius of height between a pair's particles: how much heavier the lower one
# is in the position passes (e^-1 for one right under the other; at 1 the sand sample
# scene's heap was still moving 2.5 s after its pour ended)
BETA = 0.5  # of an overlap beyond the slop each position pass takes out (Baumgarte's factor)
# Candidate pairs per particle a sub-step's search may test at most: a resting heap has about
# 30, a few fast particles among many add a pass over all of them each; particles piled on one
# spot make n / 2 each (fuzz seed 589: 540,000 born at one point in 13 frames of pre-roll
# filled 15 GB before the machine ran out)
CROWD = 1000
PASSES = 4  # position passes per velocity sweep, at most (they stop once no pair is over: at 2,
#             two grains side by side at a 10,000-grain heap's foot, squeezed by its sideways
#             load, were left 1.33 % of a radius deep)


@dataclass(frozen=True)
class ParticleCollisions:
    """Collisions among the particles of ``emitters`` (empty: all), each a sphere of its size.

    Args:
        name: the force object's name (messages). restitution: 0 .. 1 of the approach speed
        kept along the normal. friction: Coulomb's mu between particles. iterations:
        Gauss-Seidel sweeps per sub-step (more: stiffer heaps, less overlap in tall ones).
        emitters: member emitters' indices.
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
        """No step bound: impulses are clamped, speculative contacts never overshoot."""
        return math.inf

    def resolve(self, x: np.ndarray, v: np.ndarray, x0: np.ndarray, v0: np.ndarray,
                radius: np.ndarray, mass: np.ndarray, emitter: np.ndarray, h: float,
                rest_speed: float, support: tuple | None = None,
                ids: np.ndarray | None = None, warm: tuple | None = None,
                up: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, int, tuple]:
        """The sub-step's particle-particle collisions.

        Args:
            x, v: (n, 3) positions and velocities at the sub-step's end (after colliders).
            x0, v0: (n, 3) at its start. radius, mass: (n,). emitter: (n,) emitter indices.
            h: the sub-step [s]. rest_speed: approach speeds below it do not bounce [m/s].
            support: (indices, normals (k, 3), frictions (k,), surface velocities (k, 3)) of
                the particles resting on a collider: a neighbour cannot push them into it
                (the collider takes that push, as the ground holds up a heap) and its
                friction holds them.
            ids: (n,) the particles' unique ids; warm: the last sub-step's (pair keys,
                normal impulses, friction impulses), returned by it: pairs still in contact
                start from the impulses they had (a heap holds its weight from the first
                pass).
            up: (3,) the unit vector against gravity (None: no gravity): the position
                passes lift the upper particle of a pair more than the lower one.

        Returns:
            New (x, v), the number of pairs that touched and the warm start for the next
            sub-step.
        """
        members = (np.arange(len(x)) if not self.emitters
                   else np.flatnonzero(np.isin(emitter, self.emitters)))
        none = (np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 3)))
        if len(members) < 2:
            return x, v, 0, none
        xm, x0m, vm = x[members], x0[members], v[members].copy()
        floor = _supported(members, support, len(x))
        r, w = radius[members], 1.0 / mass[members]
        i, j = _swept_pairs(x0m, xm, r, self.name)
        d0 = x0m[i] - x0m[j]
        dist = norm_rows(d0)
        reach = r[i] + r[j]
        gap = dist - reach
        normal = np.where(dist[:, None] > 1e-12, d0 / np.maximum(dist, 1e-300)[:, None],
                          np.array([0.0, 0.0, 1.0]))  # two centres at one place: any axis
        # the pairs that can meet this sub-step (their closing motion covers their gap), and
        # those within SLACK of it (a neighbour's push can bring them together)
        closing = -dot_rows((xm[i] - x0m[i]) - (xm[j] - x0m[j]), normal)
        near = gap <= np.maximum(closing, 0.0) + SLACK * reach
        i, j, normal, gap, reach = i[near], j[near], normal[near], gap[near], reach[near]
        if not len(i):
            return x, v, 0, none
        share = _share(w, i, j, normal, floor)
        approach = dot_rows(v0[members][i] - v0[members][j], normal)
        meets = approach * h < -np.maximum(gap, 0.0)  # it would touch within the step
        bounce = meets & (approach < -rest_speed)
        # the least relative normal velocity: a bounce, closing no more than the gap, or
        # parting an overlap (with the bias; without it in the relax passes)
        lower = np.where(bounce, -self.restitution * approach,
                         -np.maximum(gap + SLOP * reach, 0.0) / h)
        start_v = vm.copy()
        keys = _pair_keys(ids, members, i, j)
        # accumulated normal and friction impulses (as relative velocities), from where the
        # last sub-step left them: the friction within its cone in the new contact plane
        taken, rubbed = _warm(keys, warm)
        rubbed -= dot_rows(rubbed, normal)[:, None] * normal
        rubbed *= _within(norm_rows(rubbed), self.friction * taken)[:, None]
        _move(vm, i, j, normal * taken[:, None] + rubbed, share[0])
        _hold(vm, np.flatnonzero(floor.held), floor)
        groups = [_Group.of(g, i, j, floor)
                  for g in colour(np.stack([i, j], axis=1), np.ones(len(members), bool))]
        _Solve(i, j, normal, share, floor, self.friction, groups, taken, rubbed).sweeps(
            vm, lower, self.iterations)
        new = _apart(xm + h * (vm - start_v), vm, w, i, j, reach, floor, x0m,
                     self.friction, h, PASSES * self.iterations, groups, up)
        x, v = x.copy(), v.copy()
        x[members], v[members] = new, vm
        touching = taken > 0.0
        return x, v, int(touching.sum()), (keys[touching], taken[touching], rubbed[touching])


class _Solve(NamedTuple):
    """Sequential impulses over the pairs (i, j) with their normals, shares (:func:`_share`),
    the colliders under the particles, friction, the colour groups (:class:`_Group`) and the
    accumulated normal (c,) and friction (c, 3) impulses (updated in place)."""

    i: np.ndarray
    j: np.ndarray
    normal: np.ndarray
    share: tuple[np.ndarray, np.ndarray]
    floor: _Floor
    friction: float
    groups: list
    taken: np.ndarray
    rubbed: np.ndarray

    def sweeps(self, v: np.ndarray, lower: np.ndarray, count: int) -> None:
        """``count`` Gauss-Seidel sweeps on v (n, 3) in place: each pair's relative normal
        velocity at least ``lower`` (c,), its sliding taken back within Coulomb's cone; the
        groups in turn forwards and backwards (no order favoured: a heap does not walk)."""
        taken, rubbed = self.taken, self.rubbed
        for sweep in range(count):
            for group in self.groups if sweep % 2 == 0 else self.groups[::-1]:
                g, a, b = group.g, group.a, group.b
                n = self.normal[g]
                rel = v[a] - v[b]
                along = dot_rows(rel, n)
                step = np.maximum(taken[g] + lower[g] - along, 0.0) - taken[g]
                taken[g] += step
                total = rubbed[g] - _across(rel, n)
                total *= _within(norm_rows(total), self.friction * taken[g])[:, None]
                change = step[:, None] * n + total - rubbed[g]
                rubbed[g] = total
                _push(v, group, change, (self.share[0][g], self.share[1][g]), self.floor)


def _apart(x: np.ndarray, v: np.ndarray, w: np.ndarray, i: np.ndarray, j: np.ndarray,
           reach: np.ndarray, floor: _Floor, start: np.ndarray, friction: float, h: float,
           passes: int, groups: list, up: np.ndarray | None = None) -> np.ndarray:
    """Overlaps pushed apart in position only, x (n, 3) in place and returned: Gauss-Seidel
    over the pairs' colour ``groups``, each pair along its current line, until none overlaps
    more than the slop (at most ``passes``; a tall heap finishes over the next sub-steps).
    Friction acts on a push as on an impulse of its depth over h: the pair's sliding since the
    sub-step's ``start`` is taken back, and so is its sliding velocity v, each up to mu times
    the depth (over h). A particle the push presses into its collider moves along it only.
    Under gravity (``up``) the lower particle of a pair takes less of the push (STACK).

    Each group's pairs are pushed all at once, those not overlapping by nothing (their depth,
    and with it their friction, zero): what does not change within the passes is taken once."""
    if _excess(x, i, j, reach).max() <= 0.5 * SLOP * reach.min():
        return x
    height = None if up is None else x @ up
    lift = None
    if height is not None:  # i's weight over j's: e^(STACK (h_i - h_j) / radius)
        lift = np.exp(STACK * np.clip((height[i] - height[j]) / (0.5 * reach), -4.0, 4.0))
    fixed = []  # per group: what does not change within the passes
    for p in groups:
        # (the lift scales i's inverse mass: a position push only, the pair's momentum is
        # not in question)
        wi, wj = (w[p.a], w[p.b]) if lift is None else (w[p.a] * lift[p.g], w[p.b])
        share = _free_shares(wi, wj) if p.on is None else None  # (else it turns with n)
        under = None if p.on is None else (floor.normal[p.a], floor.normal[p.b])
        fixed.append((p, reach[p.g] * (1.0 - SLOP), wi, wj, share, under, start[p.a],
                      start[p.b]))
    for sweep in range(passes):
        for p, inner, wi, wj, share, under, start_a, start_b in (
                fixed if sweep % 2 == 0 else fixed[::-1]):
            xa, xb = x[p.a], x[p.b]
            d = xa - xb
            dist = norm_rows(d)
            depth = BETA * (inner - dist)
            if not depth.max() > 0.0:
                continue
            depth = np.maximum(depth, 0.0)
            n = np.where(dist[:, None] > 1e-12, d / np.maximum(dist, 1e-300)[:, None],
                         np.array([0.0, 0.0, 1.0]))  # two centres at one place: any axis
            grip = friction * depth
            pushes = share if share is not None else _shares(wi, wj, n, *under)
            slid = _across((xa - start_a) - (xb - start_b), n)
            slid *= _within(norm_rows(slid), grip)[:, None]
            slip = _across(v[p.a] - v[p.b], n)
            slip *= _within(norm_rows(slip), grip / h)[:, None]
            _push(x, p, depth[:, None] * n - slid, pushes, floor, hold=False)
            _push(v, p, -slip, pushes, floor)
        if _excess(x, i, j, reach).max() <= 0.5 * SLOP * reach.min():
            break
    return x


class _Group(NamedTuple):
    """One colour group's pairs: their indices ``g`` among the pairs, their particles ``a``
    and ``b`` and both as ``points`` (a then b; no particle twice), which of those rest on a
    collider (``on``; None: none does) and that collider's normal and friction."""

    g: np.ndarray
    a: np.ndarray
    b: np.ndarray
    points: np.ndarray
    on: np.ndarray | None = None
    normal: np.ndarray | None = None
    friction: np.ndarray | None = None

    @classmethod
    def of(cls, g: np.ndarray, i: np.ndarray, j: np.ndarray, floor: _Floor) -> _Group:
        a, b = i[g], j[g]
        points = np.concatenate([a, b])
        on = floor.held[points]
        if not on.any():
            return cls(g, a, b, points)
        return cls(g, a, b, points, on, floor.normal[points], floor.friction[points])


def _excess(x: np.ndarray, i: np.ndarray, j: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """How much each pair overlaps beyond the slop."""
    return reach * (1.0 - SLOP) - norm_rows(x[i] - x[j])


def _across(rel: np.ndarray, n: np.ndarray) -> np.ndarray:
    """The part of ``rel`` (c, 3) across the unit normals n."""
    return rel - dot_rows(rel, n)[:, None] * n


def _within(length: np.ndarray, limit: np.ndarray) -> np.ndarray:
    """The factor that brings vectors ``length`` long within ``limit`` (1 when they are)."""
    return np.minimum(1.0, limit / np.where(length > 0.0, length, 1.0))


def _swept_pairs(x0: np.ndarray, x1: np.ndarray, r: np.ndarray, name: str
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The pairs whose spheres' sweeps over the sub-step can meet: their boxes (the sphere at
    both ends, grown by a tenth of the radius for the pushes of the position passes) overlap,
    on the library's uniform grid with cells about a diameter wide (a fast particle's long box
    spans more cells, and only it pays for its speed)."""
    grow = 1.1 * r[:, None]
    lo, hi = np.minimum(x0, x1) - grow, np.maximum(x0, x1) + grow
    try:
        pairs = UniformGrid(cell_size=2.2 * float(np.median(r)) or None,
                            max_candidates=CROWD * len(r)).pairs(lo, hi)
    except TooManyCandidates as exc:
        raise PhysanimError(
            f"particle collisions would test {exc.candidates:,} candidate pairs among "
            f"{exc.boxes:,} particles in one sub-step (more than {CROWD:,} per particle): the "
            "particles are piled on top of each other (born at one spot faster than they can "
            "part) or fly far in a sub-step — lower the emitters' rate or size, emit from a "
            "larger source, or raise Substeps", obj=name, kind="force") from exc
    except ValueError as exc:
        raise PhysanimError(f"{exc} — the particles fly too far in a sub-step: raise "
                            "Substeps", obj=name, kind="force") from exc
    return pairs[:, 0], pairs[:, 1]


def _share(w: np.ndarray, i: np.ndarray, j: np.ndarray, n: np.ndarray, floor: _Floor
           ) -> tuple[np.ndarray, np.ndarray]:
    """Of a change of a pair's relative motion along n (i away from j, equal and opposite
    pushes) the parts i and j take, (c, 2), in inverse proportion to the masses (they sum to
    one); and which of them the pair presses into the collider under it, (c, 2) bool: such a
    particle moves only along the collider (:func:`_push`), so it takes a larger part for the
    pair to part by the same amount: w over w_i a_i + w_j a_j, a = 1 - (n . its collider's
    normal)^2 (1 for the others)."""
    wi, wj = w[i], w[j]
    if not (floor.held[i].any() or floor.held[j].any()):  # no collider under any of them
        return _free_shares(wi, wj)
    return _shares(wi, wj, n, floor.normal[i], floor.normal[j])


def _free_shares(wi: np.ndarray, wj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_share` for pairs with no collider under them (inverse masses wi, wj (c,))."""
    share = np.stack([wi, wj], axis=1) / (wi + wj)[:, None]
    return share, np.zeros(share.shape, bool)


def _shares(wi: np.ndarray, wj: np.ndarray, n: np.ndarray, fi: np.ndarray, fj: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_share` given the pairs' inverse masses wi, wj (c,) and the normals fi, fj (c, 3)
    of the colliders under i and j (zero: none)."""
    ci, cj = dot_rows(n, fi), dot_rows(n, fj)
    block = np.stack([ci < 0.0, cj > 0.0], axis=1)  # i is pushed along +n, j along -n
    ai = np.where(block[:, 0], 1.0 - ci * ci, 1.0)
    aj = np.where(block[:, 1], 1.0 - cj * cj, 1.0)
    denom = wi * ai + wj * aj
    free = denom <= 1e-9 * (wi + wj)  # pressed both ways: let both move
    denom = np.where(free, wi + wj, denom)
    return np.stack([wi, wj], axis=1) / denom[:, None], block & ~free[:, None]


def _push(v: np.ndarray, group: _Group, change: np.ndarray,
          share: tuple[np.ndarray, np.ndarray], floor: _Floor, hold: bool = True) -> None:
    """One group's pairs (no particle twice): v[i] += share_i * change, v[j] -= share_j *
    change (:func:`_share`: away from colliders, mass-weighted, so the pair's momentum is
    unchanged). A particle the pair presses into its collider moves only along it, by
    Coulomb's law slowed by up to its friction times the push the collider took; for the
    others, whatever points into a collider under them is taken out (:func:`_hold`; not with
    ``hold`` False: v is positions, and the colliders see the moves afterwards)."""
    part, block = share
    points = group.points
    d = np.concatenate([part[:, :1] * change, -part[:, 1:] * change])
    if group.on is None:  # (no collider under any of them)
        v[points] += d
        return
    held = np.concatenate([block[:, 0], block[:, 1]])
    if held.any():
        f = group.normal[held]
        pressed = dot_rows(d[held], f)
        along = d[held] - pressed[:, None] * f
        grip = group.friction[held] * np.abs(pressed)
        d[held] = along * (1.0 - _within(norm_rows(along), grip))[:, None]
    loose = ~held & group.on  # on a collider, not pressed into it by the pair
    if not hold:  # positions: no particle on a collider is moved into it (a pair's friction
        # taking back a neighbour's fall along it would drag it down, and the colliders'
        # response after the pass would then carry it back along its path, undoing the push
        # that parted the pair: two grains left 1.6 % of a radius inside each other)
        if loose.any():
            f = group.normal[loose]
            d[loose] -= np.minimum(dot_rows(d[loose], f), 0.0)[:, None] * f
    v[points] += d
    if hold:
        k = points[loose]
        if len(k):
            _hold(v, k, floor)


def _pair_keys(ids, members: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """A key per pair from its two particles' ids (the same pair, the same key)."""
    if ids is None:
        return np.zeros(len(i), np.int64)
    a, b = ids[members[i]], ids[members[j]]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    return lo * np.int64(1 << 31) + hi


def _warm(keys: np.ndarray, warm) -> tuple[np.ndarray, np.ndarray]:
    """The last sub-step's normal (c,) and friction (c, 3) impulses of each pair still in
    contact (zero for new pairs)."""
    taken, rubbed = np.zeros(len(keys)), np.zeros((len(keys), 3))
    if warm is None or not len(warm[0]) or not len(keys):
        return taken, rubbed
    old_keys, old_taken, *rest = warm  # a checkpoint from before friction was kept: none
    old_rubbed = rest[0] if rest else np.zeros((len(old_keys), 3))
    order = np.argsort(old_keys)
    at = np.minimum(np.searchsorted(old_keys[order], keys), len(order) - 1)
    hit = old_keys[order][at] == keys
    taken[hit] = old_taken[order][at[hit]]
    rubbed[hit] = old_rubbed[order][at[hit]]
    return taken, rubbed


class _Floor(NamedTuple):
    """The collider under each member: whether there is one (n,), its normal (n, 3; zero:
    none), friction (n,) and surface velocity (n, 3)."""

    held: np.ndarray
    normal: np.ndarray
    friction: np.ndarray
    velocity: np.ndarray


def _supported(members: np.ndarray, support, n: int) -> _Floor:
    """The colliders under the members resting on one (``support``: see ``resolve``)."""
    count = len(members)
    floor = _Floor(np.zeros(count, bool), np.zeros((count, 3)), np.zeros(count),
                   np.zeros((count, 3)))
    if support is None or not len(support[0]):
        return floor
    where = np.full(n, -1, np.int64)
    where[members] = np.arange(count)
    k = where[support[0]]
    keep = k >= 0
    floor.held[k[keep]] = True
    for mine, given in zip(floor[1:], support[1:]):
        mine[k[keep]] = np.asarray(given)[keep]
    return floor


def _hold(v: np.ndarray, k: np.ndarray, floor: _Floor) -> None:
    """Where the velocity v[k] of a particle on a collider points into it (relative to its
    surface), take that part out — the collider pushes back — and with it, by Coulomb's law,
    up to its friction times that much of the sliding along it."""
    f = floor.normal[k]
    change = v[k] - floor.velocity[k]
    along = dot_rows(change, f)
    into = np.minimum(along, 0.0)
    slide = change - along[:, None] * f
    v[k] -= into[:, None] * f + _within(norm_rows(slide), floor.friction[k] * -into)[:, None] * slide


def _move(a: np.ndarray, i: np.ndarray, j: np.ndarray, amount: np.ndarray,
          share: np.ndarray) -> None:
    """a[i] += share[:, 0] * amount, a[j] -= share[:, 1] * amount, summed over pairs."""
    n = len(a)
    for k in range(3):
        a[:, k] += (np.bincount(i, amount[:, k] * share[:, 0], minlength=n)
                    - np.bincount(j, amount[:, k] * share[:, 1], minlength=n))
