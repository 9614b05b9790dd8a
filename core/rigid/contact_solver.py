"""Soft-step contact solver (Box2D v3's "soft step", taken to 3D), vectorised over contacts.

Contacts are found once per frame (with a speculative margin); each sub-step then runs
warm start -> solve (soft, with position bias) -> integrate positions -> relax (no bias), and
restitution comes last, once per frame. Every contact point is a constraint on the relative
velocity of its two bodies along its normal (non-penetration, accumulated impulse >= 0) and two
tangents (Coulomb friction, the tangent impulse clamped to the cone mu * normal impulse).

Gauss-Seidel needs each constraint to see the velocities its predecessors left, which a numpy
pass over all contacts would not give; contacts are therefore coloured so that no two in a
colour share a dynamic body, and each colour is one vectorised pass (Jacobi within a colour is
then exactly Gauss-Seidel). Bodies that do not move under impulses (kinematic bodies, colliders)
have zero inverse mass: their rows take impulses of size zero, so they never limit colouring.

The separation of a point is tracked through the sub-steps from the bodies' motion since the
contact was found (anchors rotate with their bodies, the normal is held):
s = s_base + n . (dx_B + R_B r_B - dx_A - R_A r_A), s_base = s0 - n . (r_B - r_A).
A separated (speculative) point lets the bodies close the gap within one sub-step but no
further; an overlapping one is pushed apart softly (a spring of CONTACT_HERTZ, heavily damped,
at most MAX_PUSH m/s).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

CONTACT_HERTZ = 30.0  # stiffness of the soft contact [Hz] (at most a quarter of the step rate)
STATIC_HERTZ = 60.0  # against bodies that do not move under impulses: stiffer
DAMPING_RATIO = 10.0  # heavily over-damped: overlaps resolve without bounce
MAX_PUSH = 1.0  # [m/s] fastest overlap recovery (gentle: overlaps in a pile add up)
RESTITUTION_THRESHOLD = 1.0  # [m/s] slower impacts do not bounce (a resting stack stays put)


@dataclass(frozen=True)
class Softness:
    """Soft constraint coefficients for a spring of ``hertz`` and damping ratio ``zeta`` in an
    implicit step of h: bias_rate [1/s], mass_scale and impulse_scale (Box2D's b2MakeSoft)."""

    bias_rate: float
    mass_scale: float
    impulse_scale: float

    @classmethod
    def of(cls, hertz: float, zeta: float, h: float) -> Softness:
        if hertz == 0.0:
            return cls(0.0, 1.0, 0.0)
        omega = 2.0 * math.pi * hertz
        a1 = 2.0 * zeta + h * omega
        a2 = h * omega * a1
        a3 = 1.0 / (1.0 + a2)
        return cls(omega / a1, a2 * a3, a3)


def tangents(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (k, 3) completing each unit normal (k, 3) to an orthonormal basis."""
    helper = np.where((np.abs(n[:, 0]) < 0.57)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    return t1, np.cross(n, t1)


def colour(a: np.ndarray, b: np.ndarray, dynamic: np.ndarray) -> list[np.ndarray]:
    """Contact indices grouped so that no dynamic body appears twice in a group. Each group is
    a maximal set (greedy): it keeps taking contacts whose dynamic bodies are still free in it,
    so there are at most 2 D - 1 groups for D contacts on the busiest body."""
    left = np.arange(len(a))
    groups = []
    while len(left):
        used = np.zeros(len(dynamic), bool)
        group, candidates = [], left
        while len(candidates):
            chosen = _first_of_their_bodies(a[candidates], b[candidates], dynamic)
            picked = candidates[chosen]
            group.append(picked)
            used[a[picked]] = used[b[picked]] = True
            candidates = candidates[~chosen]
            free = ~((used[a[candidates]] & dynamic[a[candidates]])
                     | (used[b[candidates]] & dynamic[b[candidates]]))
            candidates = candidates[free]
        group = np.sort(np.concatenate(group))
        groups.append(group)
        left = np.setdiff1d(left, group, assume_unique=True)
    return groups


def _first_of_their_bodies(a: np.ndarray, b: np.ndarray, dynamic: np.ndarray) -> np.ndarray:
    """Which contacts come first (lowest position) among those of each of their dynamic bodies
    (the first contact always does)."""
    pos = np.arange(len(a))
    ends, at = np.concatenate([a, b]), np.concatenate([pos, pos])
    dyn = dynamic[ends]
    first = np.full(len(dynamic), len(a))
    np.minimum.at(first, ends[dyn], at[dyn])
    return (~dynamic[a] | (first[a] == pos)) & (~dynamic[b] | (first[b] == pos))


@dataclass
class ContactSet:
    """A frame's contact points (k) between solver bodies a and b (rows of the velocity array).

    Attributes:
        a, b: (k,) body rows. normal: (k, 3) unit, from a to b. t1, t2: (k, 3) tangents.
        ra, rb: (k, 3) anchors: the contact point from each body's centre of mass when found.
        base: (k,) base separation (see the module docstring) [m].
        friction, restitution: (k,) combined coefficients (friction: the geometric mean of the
            two sides'; restitution: their product, so a body bounces only where both are
            bouncy — a default, unbouncy box stays down on any collider).
        relative: (k,) normal relative velocity when found [m/s] (for restitution).
        impulse: (k, 3) accumulated impulse along normal, t1, t2 [N s].
        total: (k,) sum of the normal impulses applied this frame (0: never touched).
        key: (k,) the pair of bodies (lower row * N + higher row).
        static: (k,) True when one side does not move under impulses.
        slots: (m, S) the points of each manifold (the contacts of one pair), -1 padded.
        groups: colour groups of manifolds (index arrays into ``slots``): no dynamic body is in
            two manifolds of a group.
    """

    a: np.ndarray
    b: np.ndarray
    normal: np.ndarray
    t1: np.ndarray
    t2: np.ndarray
    ra: np.ndarray
    rb: np.ndarray
    base: np.ndarray
    friction: np.ndarray
    restitution: np.ndarray
    relative: np.ndarray
    impulse: np.ndarray
    total: np.ndarray
    key: np.ndarray
    static: np.ndarray
    slots: np.ndarray
    groups: list

    def __len__(self) -> int:
        return len(self.a)

    @property
    def dirs(self) -> np.ndarray:
        """(k, 3, 3) rows normal, t1, t2 of every contact."""
        return self._dirs

    def __post_init__(self):
        self._dirs = np.stack([self.normal, self.t1, self.t2], axis=1)


def manifolds(key: np.ndarray, a: np.ndarray, b: np.ndarray, dynamic: np.ndarray):
    """Points grouped by pair (``key`` sorted or not): (slots (m, S) point indices, -1 padded;
    colour groups of manifolds)."""
    if not len(key):
        return np.zeros((0, 1), np.int64), []
    order = np.argsort(key, kind="stable")
    uniq, first, count = np.unique(key[order], return_index=True, return_counts=True)
    rank = np.arange(len(key)) - np.repeat(first, count)
    slots = np.full((len(uniq), int(count.max())), -1, np.int64)
    slots[np.repeat(np.arange(len(uniq)), count), rank] = order
    head = slots[:, 0]
    return slots, colour(a[head], b[head], dynamic)


@dataclass
class Jacobians:
    """Per sub-step, for every contact: the angular parts of the three constraint rows
    (r x n etc., (k, 3, 3) rows n/t1/t2 for body a and b), those rows times each body's world
    inverse inertia, and the effective masses (k, 3)."""

    ang_a: np.ndarray
    ang_b: np.ndarray
    wa: np.ndarray  # (k, 3, 3): I_a^-1 (r_a x d) for the three directions d
    wb: np.ndarray
    mass: np.ndarray  # (k, 3): 1 / (m_a^-1 + m_b^-1 + (r_a x d) I_a^-1 (r_a x d) + ...)
    block: np.ndarray  # (m, S, S): pseudo-inverse of each manifold's normal coupling matrix


def jacobians(cs: ContactSet, inv_mass: np.ndarray, inv_inertia: np.ndarray, ra: np.ndarray,
              rb: np.ndarray, block: np.ndarray | None = None) -> Jacobians:
    """Constraint rows of every contact for the bodies' current world inverse inertias and
    lever arms ra, rb (k, 3): from each body's centre of mass to one common world point, so an
    impulse and its reaction act at the same point (angular momentum is conserved)."""
    dirs = cs.dirs
    ang_a = np.cross(ra[:, None, :], dirs)
    ang_b = np.cross(rb[:, None, :], dirs)
    wa = np.einsum("kij,kdj->kdi", inv_inertia[cs.a], ang_a)
    wb = np.einsum("kij,kdj->kdi", inv_inertia[cs.b], ang_b)
    k = (inv_mass[cs.a] + inv_mass[cs.b])[:, None] + np.einsum("kdi,kdi->kd", ang_a, wa) + \
        np.einsum("kdi,kdi->kd", ang_b, wb)
    if block is None:
        block = _blocks(cs, inv_mass, ang_a[:, 0], ang_b[:, 0], wa[:, 0], wb[:, 0])
    return Jacobians(ang_a, ang_b, wa, wb, np.where(k > 0.0, 1.0 / np.maximum(k, 1e-300), 0.0),
                     block)


def _blocks(cs: ContactSet, inv_mass, ang_a, ang_b, wa, wb) -> np.ndarray:
    """Per manifold, the pseudo-inverse of K_ij = J_i M^-1 J_j^T over its points' normal rows
    (one normal per manifold). Four coplanar points of a face leave K rank 3; the minimum-norm
    solution then shares the load symmetrically, where point-by-point Gauss-Seidel would
    favour whichever point comes first (and set a stack swaying)."""
    slots = cs.slots
    valid = slots >= 0
    idx = np.where(valid, slots, 0)
    head = idx[:, 0]
    normal = cs.normal[idx]  # (a manifold on a curved surface has several normals)
    k = (inv_mass[cs.a[head]] + inv_mass[cs.b[head]])[:, None, None] * \
        np.einsum("mic,mjc->mij", normal, normal) + \
        np.einsum("mic,mjc->mij", ang_a[idx], wa[idx]) + np.einsum("mic,mjc->mij", ang_b[idx], wb[idx])
    pair = valid[:, :, None] & valid[:, None, :]
    eye = np.broadcast_to(np.eye(slots.shape[1], dtype=bool), k.shape)
    k = np.where(pair, k, np.where(eye, 1.0, 0.0))  # empty slots: decoupled unit rows
    return np.linalg.pinv(k, rcond=1e-10, hermitian=True)


def apply(v: np.ndarray, w: np.ndarray, cs: ContactSet, jac: Jacobians, idx: np.ndarray,
          d_impulse: np.ndarray, inv_mass: np.ndarray) -> None:
    """Apply impulse changes (len(idx), 3) along normal/t1/t2 of contacts ``idx``: body b
    gains, body a loses. Within a colour each dynamic body appears once, so plain indexed
    writes are exact; static rows get zero changes."""
    dirs = cs.dirs[idx]
    p = np.einsum("kd,kdi->ki", d_impulse, dirs)
    a, b = cs.a[idx], cs.b[idx]
    v[a] -= inv_mass[a][:, None] * p
    w[a] -= np.einsum("kd,kdi->ki", d_impulse, jac.wa[idx])
    v[b] += inv_mass[b][:, None] * p
    w[b] += np.einsum("kd,kdi->ki", d_impulse, jac.wb[idx])


def relative_velocity(v, w, cs: ContactSet, jac: Jacobians, idx: np.ndarray) -> np.ndarray:
    """(len(idx), 3) relative velocity of b's anchor against a's along normal, t1, t2."""
    a, b = cs.a[idx], cs.b[idx]
    dirs = cs.dirs[idx]
    return (np.einsum("kdi,ki->kd", dirs, v[b] - v[a])
            + np.einsum("kdi,ki->kd", jac.ang_b[idx], w[b])
            - np.einsum("kdi,ki->kd", jac.ang_a[idx], w[a]))


def solve(v, w, cs: ContactSet, jac: Jacobians, inv_mass, separation: np.ndarray, h: float,
          soft: Softness, static_soft: Softness, use_bias: bool) -> None:
    """One Gauss-Seidel sweep, colour by colour: each manifold's normal impulses solved
    together (a block, falling back to point by point when one would pull), then friction
    point by point."""
    for group in cs.groups:
        slots = cs.slots[group]
        valid = slots >= 0
        scales = _scales(cs, separation, np.where(valid, slots, 0), h, soft, static_soft,
                         use_bias)
        pulling = _normal_block(v, w, cs, jac, group, slots, valid, scales, inv_mass)
        if pulling.any():
            for k in range(slots.shape[1]):
                seq = pulling & valid[:, k]
                if seq.any():
                    _normal_points(v, w, cs, jac, slots[seq, k], [x[seq, k] for x in scales],
                                   inv_mass)
        _friction(v, w, cs, jac, slots, valid, inv_mass)


def _scales(cs, separation, idx, h, soft, static_soft, use_bias):
    """(bias, mass scale, impulse scale), each shaped like ``idx``: a separated (speculative)
    point may close its gap within the sub-step but no further; an overlap is pushed out
    softly (with bias) or not at all (relax)."""
    s = separation[idx]
    stat = cs.static[idx]
    speculative = s > 0.0
    if not use_bias:
        return np.where(speculative, s / h, 0.0), np.ones_like(s), np.zeros_like(s)
    rate = np.where(stat, static_soft.bias_rate, soft.bias_rate)
    m_scale = np.where(stat, static_soft.mass_scale, soft.mass_scale)
    i_scale = np.where(stat, static_soft.impulse_scale, soft.impulse_scale)
    bias = np.where(speculative, s / h, np.maximum(m_scale * rate * s, -MAX_PUSH))
    return bias, np.where(speculative, 1.0, m_scale), np.where(speculative, 0.0, i_scale)


def _normal_block(v, w, cs, jac, group, slots, valid, scales, inv_mass) -> np.ndarray:
    """Solve each manifold's normal impulses at once; returns which manifolds would pull
    (a negative impulse) and are left to the point-by-point pass."""
    bias, m_scale, i_scale = scales
    idx = np.where(valid, slots, 0)
    rel = relative_velocity(v, w, cs, jac, idx.ravel())[:, 0].reshape(idx.shape)
    fresh = valid & (cs.total[idx] == 0.0)  # not touched yet this frame: its approach speed
    cs.relative[idx[fresh]] = rel[fresh]
    old = np.where(valid, cs.impulse[idx, 0], 0.0)
    rhs = np.where(valid, m_scale * rel + bias, 0.0)
    d = np.where(valid, -np.einsum("gij,gj->gi", jac.block[group], rhs) - i_scale * old, 0.0)
    pulling = ((old + d < 0.0) & valid).any(axis=1)
    d = np.where(pulling[:, None], 0.0, d)
    head = idx[:, 0]
    a, b = cs.a[head], cs.b[head]
    p = np.einsum("gs,gsi->gi", d, cs.normal[idx])
    v[a] -= inv_mass[a][:, None] * p
    v[b] += inv_mass[b][:, None] * p
    w[a] -= np.einsum("gs,gsi->gi", d, jac.wa[idx, 0])
    w[b] += np.einsum("gs,gsi->gi", d, jac.wb[idx, 0])
    done = valid & ~pulling[:, None]
    cs.impulse[idx[done], 0] = (old + d)[done]
    cs.total[idx[done]] += d[done]
    return pulling


def _normal_points(v, w, cs, jac, pts, scales, inv_mass) -> None:
    """Normal impulses of points ``pts`` (one per manifold), each alone, clamped >= 0."""
    bias, m_scale, i_scale = scales
    rel = relative_velocity(v, w, cs, jac, pts)[:, 0]
    fresh = cs.total[pts] == 0.0
    cs.relative[pts[fresh]] = rel[fresh]
    old = cs.impulse[pts, 0]
    new = np.maximum(old - jac.mass[pts, 0] * (m_scale * rel + bias) - i_scale * old, 0.0)
    d = np.zeros((len(pts), 3))
    d[:, 0] = new - old
    cs.impulse[pts, 0] = new
    cs.total[pts] += d[:, 0]
    apply(v, w, cs, jac, pts, d, inv_mass)


def _friction(v, w, cs, jac, slots, valid, inv_mass) -> None:
    """Coulomb friction of every point of the manifolds ``slots`` (g, S): each point's two
    tangent impulses from the same velocities, shared (divided by the manifold's point count,
    so the points together do what one would alone: symmetric, as the normal block), then
    clamped to its cone friction * normal impulse; applied per manifold."""
    idx = np.where(valid, slots, 0)
    flat = idx.ravel()
    rel_t = relative_velocity(v, w, cs, jac, flat)[:, 1:].reshape(idx.shape + (2,))
    count = valid.sum(axis=1)[:, None, None]
    old = cs.impulse[idx, 1:]
    new = old - jac.mass[idx, 1:] * rel_t / np.maximum(count, 1)
    limit = cs.friction[idx] * cs.impulse[idx, 0]
    norm = np.linalg.norm(new, axis=2)
    new *= np.where(norm > limit, limit / np.maximum(norm, 1e-300), 1.0)[..., None]
    d = np.where(valid[..., None], new - old, 0.0)
    cs.impulse[idx[valid], 1:] = new[valid]
    _apply_manifolds(v, w, cs, jac, idx, d, inv_mass, rows=slice(1, 3))


def _apply_manifolds(v, w, cs, jac, idx, d, inv_mass, rows) -> None:
    """Apply impulse changes d (g, S, r) along the contact directions ``rows`` of the points
    idx (g, S) of g manifolds (no dynamic body in two of them): summed per manifold."""
    p = np.einsum("gsr,gsri->gi", d, cs.dirs[idx][:, :, rows])
    head = idx[:, 0]
    a, b = cs.a[head], cs.b[head]
    v[a] -= inv_mass[a][:, None] * p
    v[b] += inv_mass[b][:, None] * p
    w[a] -= np.einsum("gsr,gsri->gi", d, jac.wa[idx][:, :, rows])
    w[b] += np.einsum("gsr,gsri->gi", d, jac.wb[idx][:, :, rows])


def warm_start(v, w, cs: ContactSet, jac: Jacobians, inv_mass) -> None:
    """Apply the accumulated impulses (from the last sub-step, or the last frame's contacts
    at the same place) before solving: resting contacts start where they ended."""
    for group in cs.groups:
        slots = cs.slots[group]
        valid = slots >= 0
        idx = np.where(valid, slots, 0)
        cs.total[idx[valid]] += cs.impulse[idx[valid], 0]
        d = np.where(valid[..., None], cs.impulse[idx], 0.0)
        _apply_manifolds(v, w, cs, jac, idx, d, inv_mass, rows=slice(0, 3))


def _by_slot(cs: ContactSet):
    """Point index arrays in which no dynamic body appears twice: per colour, per slot."""
    for group in cs.groups:
        slots = cs.slots[group]
        for k in range(slots.shape[1]):
            pts = slots[:, k][slots[:, k] >= 0]
            if len(pts):
                yield pts


def restitution(v, w, cs: ContactSet, jac: Jacobians, inv_mass) -> None:
    """Bounce: contacts that were approaching faster than RESTITUTION_THRESHOLD when first
    touched (within the frame) and took an impulse leave at restitution times that speed; each
    bounces once (its approach speed is then forgotten)."""
    for idx in _by_slot(cs):
        sel = idx[(cs.restitution[idx] > 0.0) & (cs.relative[idx] < -RESTITUTION_THRESHOLD)
                  & (cs.total[idx] > 0.0)]
        if not len(sel):
            continue
        rel = relative_velocity(v, w, cs, jac, sel)[:, 0]
        n_old = cs.impulse[sel, 0]
        n_new = np.maximum(n_old - jac.mass[sel, 0] * (rel + cs.restitution[sel] * cs.relative[sel]),
                           0.0)
        d = np.zeros((len(sel), 3))
        d[:, 0] = n_new - n_old
        cs.impulse[sel, 0] = n_new
        cs.relative[sel] = 0.0
        apply(v, w, cs, jac, sel, d, inv_mass)
