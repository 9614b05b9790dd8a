"""Pairs of weighted point sums kept apart along a normal: (sum_k w_k x_k - anchor) . n >= gap
for each pair, over points of one system (weights signed: a point against a triangle is its
triangle's barycentric weights and minus one for the point; ``anchor`` is a part that does not
move, a collider's feature). Shared by colliders' features against faces (:mod:`.features`)
and a mesh against itself.

* :func:`separate` restores the gaps: each pair's shortfall s is removed by moving its points
  along n by w_k m_k^-1 s / sum_j w_j^2 m_j^-1 (the impulse that moves the weighted sum by
  exactly s), Gauss-Seidel over groups of pairs that share no moving point
  (:func:`..colouring.colour`: each group one vectorised step), or relaxed Jacobi passes
  where pairs crowd on few points.
* :func:`respond` does the same for velocities: the weighted sum's approach along n is
  cancelled (a bounce of restitution times it when faster than the rest speed); then Coulomb
  friction on its sliding, each pair's friction impulse within mu times the whole normal
  impulse it took (crowded pairs' friction by accelerated projected gradient passes:
  :func:`_accelerated_friction`).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..colouring import colour
from ..forces.springs import scatter_add
from ..transforms import divide_rows, dot_rows, norm_rows, row_any, row_max, scale_rows

PASSES = 16  # position passes at most
TOLERANCE = 0.05  # a pass leaving every pair within this fraction of the gap is the last
VELOCITY_PASSES = 4  # Gauss-Seidel velocity passes at most
RELAXED_PASSES = 32  # crowded pairs' velocity passes at most (relaxed Jacobi, accelerated friction)
RELAXED_TOLERANCE = 1e-3  # of the rest speed: relaxed normal passes end once no pair approaches
# faster (Gauss-Seidel's end once none approaches at all: each of its pairs is solved exactly)
SLIDE_TOLERANCE = 1e-4  # of the rest speed: a friction pass changing no slide more is the last
CROWD = 12  # pairs on one point beyond which passes are relaxed Jacobi, not coloured
MIN_SHARE = 0.25  # of a pair's weight on moving points, below which pinned ones hold it


class PointPairs(NamedTuple):
    """c pairs.

    Attributes:
        vertex: (c, k) point indices (a row may repeat a point with weight 0).
        weight: (c, k) signed weights.
        normal: (c, 3) unit directions the weighted sum must keep its distance along.
        anchor: (c, 3) the still part (zero: none).
        depth: (c,) the separation when found (negative: crossed or overlapping).
        gap: the distance to keep.
    """

    vertex: np.ndarray
    weight: np.ndarray
    normal: np.ndarray
    anchor: np.ndarray
    depth: np.ndarray
    gap: float

    def take(self, rows) -> PointPairs:
        return PointPairs(*(a[rows] for a in self[:5]), self.gap)

    @classmethod
    def joined(cls, parts: list[PointPairs]) -> PointPairs:
        return cls(*(np.concatenate(a) for a in zip(*(p[:5] for p in parts))), parts[0].gap)


def shares(pairs: PointPairs, inv_mass: np.ndarray):
    """Each pair's points' shares of a push (weight times inverse mass, (c, k)), their sum
    against the weights (c,), and the pairs a push can move: at least MIN_SHARE of their
    weight on points that move (one nearer a pinned point than that is held by it: moving
    the rest would take a push of the shortfall over that weight)."""
    share = pairs.weight * inv_mass[pairs.vertex]
    denom = np.einsum("ck,ck->c", pairs.weight, share)
    size = np.abs(pairs.weight)
    movable = np.where(share != 0.0, size, 0.0).sum(axis=1) / np.maximum(size.sum(axis=1),
                                                                         1e-300)
    return share, denom, np.nonzero((denom > 0.0) & (movable >= MIN_SHARE))[0]


def _groups(pairs: PointPairs, rows: np.ndarray, inv_mass: np.ndarray,
            coloured: bool | None) -> list | None:
    """Gauss-Seidel's groups of pairs that share no moving point; or None (``coloured``
    False, or None and some moving point in more than CROWD pairs): relaxed Jacobi passes
    (:func:`_apply`) — a heap puts dozens of pairs on a point, which would take as many
    colours as the passes it saves."""
    vertex = pairs.vertex[rows]
    if coloured is None:
        moving = vertex[inv_mass[vertex] > 0.0]
        coloured = not len(moving) or np.bincount(moving).max() <= CROWD
    return colour(vertex, inv_mass > 0.0) if coloured else None


def _apply(x: np.ndarray, vertex: np.ndarray, share: np.ndarray, impulse: np.ndarray,
           relax: bool):
    """x[vertex] += share (x) impulse: each pair's points (c, k) moved by their shares (c, k)
    of its impulse (c, 3). ``relax``: a Jacobi pass — each pair's impulse scaled by one over
    the most pairs moving any of its points, the same factor for all its points, so a pair's
    equal and opposite impulses stay so (momentum kept) and no point takes more than about
    one full push. Returns the share of each pair's impulse applied ((c,) or 1.0)."""
    scale = 1.0
    if relax:
        moves = (share != 0.0) & row_any(impulse != 0.0)[:, None]
        count = np.bincount(vertex[moves], minlength=len(x))
        scale = 1.0 / np.maximum(row_max(np.where(moves, count[vertex], 0)), 1)
        impulse = scale_rows(impulse, scale)
    scatter_add(x, vertex, _outer(share, impulse))
    return scale


def _outer(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(c, k, 3) per pair the outer product of its k shares (c, k) and its vector (c, 3): a
    stack of (k, 1) x (1, 3) products, the same values as the broadcast
    ``a[:, :, None] * b[:, None, :]`` (which numpy 1.26 runs 3 row by 3 row: 2.5 x slower at
    2,000 pairs)."""
    return np.matmul(a[:, :, None], b[:, None, :])


def within_cone(tangent: np.ndarray, bound: np.ndarray) -> np.ndarray:
    """Friction impulses or forces (c, 3) scaled down, each to at most its ``bound`` (c,)
    (mu times its normal one), in place; returned."""
    return scale_rows(tangent, np.minimum(1.0, bound / np.maximum(norm_rows(tangent), 1e-300)),
                      out=tangent)


class _Part(NamedTuple):
    """Rows ``rows`` of the pairs and their arrays (points, weights, normals, the still part —
    the anchors, or their velocities —, shares, sums), gathered once for all the passes."""

    rows: np.ndarray
    vertex: np.ndarray
    weight: np.ndarray
    normal: np.ndarray
    still: np.ndarray
    share: np.ndarray
    denom: np.ndarray

    @classmethod
    def of(cls, rows: np.ndarray, *arrays: np.ndarray) -> _Part:
        return cls(rows, *(a[rows] for a in arrays))

    def take(self, mask: np.ndarray) -> _Part:
        return _Part(*(a[mask] for a in self))


def separate(pairs: PointPairs, x: np.ndarray, inv_mass: np.ndarray,
             coloured: bool | None = True) -> np.ndarray | None:
    """Restore the pairs' gaps in x (n, 3), in place (``coloured``: see :func:`_groups`).
    Returns the points moved, or None when no pair was short."""
    vertex, weight, normal = pairs.vertex, pairs.weight, pairs.normal
    share, denom, rows = shares(pairs, inv_mass)

    def short(p: _Part):
        q = np.einsum("ck,ckj->cj", p.weight, x[p.vertex])
        return pairs.gap - dot_rows(q - p.still, p.normal)

    arrays = (vertex, weight, normal, pairs.anchor, share, denom)
    every = _Part.of(rows, *arrays)
    if not len(rows) or short(every).max() <= TOLERANCE * pairs.gap:
        return None
    groups = _groups(pairs, rows, inv_mass, coloured)
    relax = groups is None
    parts = [every] if relax else [_Part.of(rows[g], *arrays) for g in groups]
    for _ in range(PASSES):
        for p in parts:
            step = np.maximum(short(p), 0.0) / p.denom
            _apply(x, p.vertex, scale_rows(p.share, step), p.normal, relax)
        if short(every).max() <= TOLERANCE * pairs.gap:
            break
    return np.unique(vertex[rows])


def respond(pairs: PointPairs, v: np.ndarray, inv_mass: np.ndarray, normal: np.ndarray,
            surface: np.ndarray, friction: float, restitution: float, rest_speed: float,
            coloured: bool | None = True, impulses: list | None = None) -> np.ndarray:
    """Velocities v (n, 3) [m/s] in place: each pair's weighted sum stops approaching the
    anchor's velocity ``surface`` (c, 3) along ``normal`` (c, 3) (world directions) — passes
    until none approaches — then friction passes stop or slow its sliding, each pair's
    friction impulse (summed over the passes) held within ``friction`` times the normal
    impulse it took in all of them. (Friction bounded by one pass's part let the layers of a
    resting pile creep over each other: where a heap crowds dozens of pairs on a point, the
    relaxed passes give each pair a small part of its push at a time. Friction interleaved
    with the normal passes made the Gauss-Seidel order show: a cloth striking a box square
    spun it five times faster.) ``coloured``: see :func:`_groups`. Relaxed normal passes
    (crowded points) end once no pair approaches faster than RELAXED_TOLERANCE of the rest
    speed: each gives a pair only a part of its push, so an approach never reaches exactly
    zero, and all RELAXED_PASSES ran, the last ones for approaches of 1e-9 m/s. (Gauss-Seidel
    passes end once none approaches at all; such a tolerance there left a cloth draped on
    Suzanne creeping, never asleep.) Crowded pairs' friction: :func:`_accelerated_friction`.
    ``impulses``: a list, given each row's normal impulse (c,)
    and friction impulse (c, 3) (per unit weight: point k of a row took weight_k times them).
    Returns the pairs that can move (rows)."""
    vertex, weight = pairs.vertex, pairs.weight
    share, denom, rows = shares(pairs, inv_mass)
    groups = _groups(pairs, rows, inv_mass, coloured) if len(rows) else []
    relax = groups is None
    # each group's rows of the pairs' arrays, gathered once for all the passes
    arrays = (vertex, weight, normal, surface, share, denom)
    every = _Part.of(rows, *arrays)
    parts = [every] if relax else [_Part.of(rows[g], *arrays) for g in groups]

    def normal_speed(p: _Part):
        rel = np.einsum("ck,ckj->cj", p.weight, v[p.vertex]) - p.still
        return rel, dot_rows(rel, p.normal)

    def push(vertex, share, impulse):  # impulse (per unit weight) (g, 3) on pairs of these
        return _apply(v, vertex, share, impulse, relax)  # points and shares: the share applied

    _, vn = normal_speed(every)
    # what each pair's normal speed must reach: a bounce when approaching faster than the
    # rest speed, resting contact when slower, nothing for a separating pair
    e = restitution
    floor = np.full(len(vertex), -np.inf)
    floor[rows] = np.where(vn < 0.0, np.where(-e * vn > rest_speed, -e * vn, 0.0), -np.inf)
    floors = [floor[p.rows] for p in parts]
    pushed = np.zeros(len(vertex))  # each pair's normal impulse so far
    held = np.zeros((len(vertex), 3))  # and its friction impulse
    still = SLIDE_TOLERANCE * rest_speed  # a friction change below this (m/s) changes nothing
    # a relaxed pass finding no pair short of its target speed by more than this is the last
    enough = RELAXED_TOLERANCE * rest_speed if relax else 0.0
    passes = RELAXED_PASSES if relax else VELOCITY_PASSES
    for _ in range(passes):
        changed = False
        for p, f in zip(parts, floors):
            _, vn = normal_speed(p)
            dvn = np.maximum(f - vn, 0.0)
            if dvn.any():
                changed = changed or dvn.max() > enough
                step = dvn / p.denom
                pushed[p.rows] += step * push(p.vertex, p.share, scale_rows(p.normal, step))
        if not changed:
            break
    if impulses is not None:
        impulses[:] = [pushed, held]
    if friction <= 0.0:
        return rows
    parts = [p.take(pushed[p.rows] > 0.0) for p in parts]
    if relax:
        p = parts[0]
        if len(p.rows):
            held[p.rows] = _accelerated_friction(p, v, friction * pushed[p.rows], still, passes)
        return rows
    for _ in range(passes):
        changed = False
        for p in parts:
            if not len(p.rows):
                continue
            rel, vn = normal_speed(p)
            slide = rel - scale_rows(p.normal, vn)
            # the impulse that stops the slide, within the cone
            was = held[p.rows]
            want = within_cone(was - divide_rows(slide, p.denom), friction * pushed[p.rows])
            delta = want - was
            moved = norm_rows(delta) * p.denom > still
            if moved.any():
                changed = True
                delta = delta[moved]
                push(p.vertex[moved], p.share[moved], delta)  # (whole: Gauss-Seidel's)
                held[p.rows[moved]] += delta
        if not changed:
            break
    return rows


def _accelerated_friction(p: _Part, v: np.ndarray, bound: np.ndarray, still: float,
                          passes: int) -> np.ndarray:
    """Crowded pairs' friction impulses (c, 3) (per unit weight, each within its ``bound``),
    v (n, 3) changed by them in place: the impulses that stop the pairs' slides as far as
    their cones let them, by Nesterov's accelerated projected gradient with adaptive restart
    (O'Donoghue & Candes 2015; Mazhar et al. 2015 for friction cones). Each pair's step is
    one over its sum ``denom`` times the most pairs on any of its points, which bounds the
    pairs' coupling (Cauchy-Schwarz over each point's pairs), so the passes converge. Relaxed
    Jacobi passes (each pair a part of its move to the cone, the part one over those pairs)
    took a sliding pair that far towards its bound in each pass: after its 32 passes a
    heap's slides were still 2-8 % of the rest speed from the answer, where these end once
    no pair's impulse changes by more than ``still`` (m/s: the change over the pair's step,
    a slide speed) in 2-21 passes. Every pass pushes a pair's points by their shares of its
    impulse, as the other passes do (equal and opposite where its weights sum to zero)."""
    points, local = np.unique(p.vertex, return_inverse=True)
    local = local.reshape(p.vertex.shape)
    moves = p.share != 0.0
    count = np.bincount(local[moves], minlength=len(points))
    step = 1.0 / (p.denom * np.maximum(row_max(np.where(moves, count[local], 0)), 1))
    u = v[points]  # the points' velocities at the impulses so far
    ahead, u_ahead = np.zeros((len(p.rows), 3)), u  # and at the point extrapolated to
    held, theta = ahead, 1.0
    for _ in range(passes):
        rel = np.einsum("ck,ckj->cj", p.weight, u_ahead[local]) - p.still
        slide = rel - scale_rows(p.normal, dot_rows(rel, p.normal))
        new = within_cone(ahead - scale_rows(slide, step), bound)
        change = new - ahead
        u_new = u_ahead.copy()
        scatter_add(u_new, local, _outer(p.share, change))
        if (norm_rows(change) / step).max() <= still:
            held, u = new, u_new
            break
        following = 0.5 * theta * (np.sqrt(theta * theta + 4.0) - theta)
        if np.vdot(slide, new - held) > 0.0:  # the slides' energy rose: start again from here
            ahead, u_ahead, theta = new, u_new, 1.0
        else:
            beta = theta * (1.0 - theta) / (theta * theta + following)
            ahead, u_ahead, theta = new + beta * (new - held), u_new + beta * (u_new - u), following
        held, u = new, u_new
    v[points] = u
    return held
