"""Soft-step contact solver (Box2D v3's "soft step", taken to 3D), vectorised over contacts.

Contacts are found with a speculative margin (:mod:`.collide`); each sub-step then runs
warm start -> solve (soft, with position bias) -> integrate positions -> relax (no bias) ->
restitution. Every contact point is a constraint on the relative velocity of its two bodies
along its normal (non-penetration, accumulated impulse >= 0) and two tangents (Coulomb
friction, the tangent impulse clamped to the cone mu * normal impulse).

Layout (:mod:`.contact_set`): the points of one pair of bodies form a manifold; manifolds are padded to S slots
(empty slots have zero rows and take no impulse) and ordered by colour, so that no dynamic
body is in two manifolds of one colour. Gauss-Seidel needs each constraint to see the
velocities its predecessors left, which one numpy pass over all contacts would not give; each
colour is therefore one vectorised pass over a contiguous slice (Jacobi within a colour is then
exactly Gauss-Seidel). Velocities are one (N, 6) array [v, w]; a constraint row is 12 numbers
over [v_a, w_a, v_b, w_b], and the row times the inverse masses (what a unit impulse along it
does to those velocities) is precomputed once per sub-step, so a colour's pass is a gather,
a few small products and a scatter. Bodies that impulses do not move (kinematic bodies,
colliders, sleepers) have zero inverse mass: they take no velocity change, so they never limit
colouring.

The separation of a point follows the bodies from where the contact was found (its anchors,
each body's surface point, move with their bodies; the normal is held): s = n . (p_B - p_A),
p the anchors' world positions. A separated (speculative) point lets the bodies close the gap within one sub-step
but no further; an overlapping one is pushed apart softly (a spring of CONTACT_HERTZ, heavily
damped, at most MAX_PUSH m/s).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..forces.springs import scatter_add
from ..transforms import cross, row_all, row_any, row_max, take
from . import manifold_blocks as blocks
from .contact_set import ContactSet, subset_width

CONTACT_HERTZ = 30.0  # stiffness of the soft contact [Hz] (at most a quarter of the step rate)
STATIC_HERTZ = 60.0  # against bodies that do not move under impulses: stiffer
DAMPING_RATIO = 10.0  # heavily over-damped: overlaps resolve without bounce
MAX_PUSH = 1.0  # [m/s] fastest overlap recovery (gentle: overlaps in a pile add up)
RESTITUTION_THRESHOLD = 1.0  # [m/s] slower impacts do not bounce (a resting stack stays put)
PIVOTS = 2  # principal pivoting steps of a manifold whose block solution pulls
IMPACT_PASSES = 8  # sweeps of the impacts between dynamic bodies (a row of 8 balls passes on)


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


@dataclass
class Rows:
    """The constraint rows of every slot at the bodies' current poses, over the velocities
    [v_a, w_a, v_b, w_b] of the manifold's bodies.

    Attributes:
        jn: (M, S, 12) normal rows. mn: (M, S, 12) the same times the inverse masses (the
            velocity change of a unit normal impulse). mass_n: (M, S) effective masses.
        jt, mt: (M, 2 S, 12) tangent rows (t1, t2 of slot 0, then of slot 1, ...) and the
            velocity changes. mass_t: (M, 2 S) effective masses shared over the manifold's
            points (divided by their count: together they do what one point would alone).
    """

    jn: np.ndarray
    mn: np.ndarray
    mass_n: np.ndarray
    jt: np.ndarray
    mt: np.ndarray
    mass_t: np.ndarray


def rows(cs: ContactSet, inv_mass: np.ndarray, inv_inertia: np.ndarray, ra: np.ndarray,
         rb: np.ndarray) -> Rows:
    """Rows for world inverse inertias (N, 3, 3) and lever arms ra, rb (M, S, 3) from each
    body's centre of mass to one common world point (an impulse and its reaction act at the
    same point, so angular momentum is conserved). Sets the blocks of new manifolds.

    Every row of a manifold is built at once in one (M, 3 S, 12) array: the S normal rows,
    then the 2 S tangent rows; the Rows are views of it. The directions and the linear parts
    do not change while the contacts are kept (for the same inverse masses): they are written
    once into arrays ``cs`` keeps, and each call writes the angular parts over the last ones
    (the last call's Rows are views of the same arrays)."""
    m, s = cs.valid.shape
    a, b = cs.ab[:, 0], cs.ab[:, 1]
    if cs.rows_buffer is None or cs.rows_buffer[0] is not inv_mass:
        slot = np.concatenate([np.arange(s), np.repeat(np.arange(s), 2)])
        dirs = np.concatenate([cs.normal, np.stack([cs.t1, cs.t2], axis=2).reshape(m, 2 * s, 3)],
                              axis=1)  # (M, 3 S, 3)
        ma, mb = inv_mass[a, None, None], inv_mass[b, None, None]
        j, mj = np.empty((2, m, 3 * s, 12))
        np.negative(dirs, out=j[..., :3])
        j[..., 6:9] = dirs
        np.multiply(-ma, dirs, out=mj[..., :3])
        np.multiply(mb, dirs, out=mj[..., 6:9])
        linear = (ma[..., 0] + mb[..., 0]) * cs.valid[:, slot]  # (unit directions; empty slots
        cs.rows_buffer = (inv_mass, slot, dirs, j, mj, linear)  # have none)
    _, slot, dirs, j, mj, linear = cs.rows_buffer
    # written in place (copies into the interleaved rows cost more than the products):
    # -(r_a x d) = d x r_a, r_b x d, and I^-1 times each (matmul: the tensors are symmetric)
    ang_a, ang_b = j[..., 3:6], j[..., 9:]
    cross(dirs, np.take(ra, slot, axis=1), out=ang_a)
    cross(np.take(rb, slot, axis=1), dirs, out=ang_b)
    np.matmul(ang_a, take(inv_inertia, a), out=mj[..., 3:6])
    np.matmul(ang_b, take(inv_inertia, b), out=mj[..., 9:])
    k = linear + np.einsum("mri,mri->mr", ang_a, mj[..., 3:6]) + \
        np.einsum("mri,mri->mr", ang_b, mj[..., 9:])
    mass = np.where(k > 0.0, 1.0 / np.maximum(k, 1e-300), 0.0)
    jn, mn = j[:, :s], mj[:, :s]
    if cs.block is None:
        cs.coupling, cs.block = np.full((2, m, s, s), np.nan)
        w = subset_width(s)
        cs.subsets = np.full((m, 1 << w, w, w), np.nan)
    new = np.nonzero(np.isnan(cs.block[:, 0, 0]))[0]
    if len(new):
        cs.coupling[new] = blocks.coupling(cs.valid[new], jn[new], mn[new])
        cs.block[new] = blocks.pinv(cs.coupling[new])
        cs.subsets[new] = blocks.subset_blocks(cs.coupling[new], cs.block[new])
    count = np.maximum(cs.valid.sum(axis=1), 1)[:, None]
    return Rows(jn, mn, mass[:, :s], j[:, s:], mj[:, s:], mass[:, s:] / count)


@dataclass
class Scales:
    """Per slot (M, S): the velocity bias [m/s], the mass and impulse scales of a solve."""

    bias: np.ndarray
    mass: np.ndarray
    impulse: np.ndarray

    @classmethod
    def of(cls, cs: ContactSet, separation: np.ndarray, h: float, soft: Softness,
           static_soft: Softness, use_bias: bool) -> Scales:
        """A separated (speculative) point may close its gap within the sub-step but no
        further; an overlap is pushed out softly (with bias) or not at all (relax)."""
        speculative = separation > 0.0
        if not use_bias:
            return cls(np.where(speculative, separation / h, 0.0), np.ones_like(separation),
                       np.zeros_like(separation))
        stat = cs.static[:, None]
        rate = np.where(stat, static_soft.bias_rate, soft.bias_rate)
        m_scale = np.where(stat, static_soft.mass_scale, soft.mass_scale)
        i_scale = np.where(stat, static_soft.impulse_scale, soft.impulse_scale)
        bias = np.where(speculative, separation / h,
                        np.maximum(m_scale * rate * separation, -MAX_PUSH))
        return cls(bias, np.where(speculative, 1.0, m_scale), np.where(speculative, 0.0, i_scale))


def _gather(vel: np.ndarray, ab: np.ndarray) -> np.ndarray:
    """(m, 12) [v_a, w_a, v_b, w_b] of manifolds with body rows ab (m, 2)."""
    return take(vel, ab).reshape(len(ab), 12)


def _scatter(vel: np.ndarray, ab: np.ndarray, local: np.ndarray) -> None:
    """Write the manifolds' velocities back. Within a colour each dynamic body is in one
    manifold; a body impulses do not move may be in several, always with its own velocity."""
    vel[ab[:, 0]] = local[:, :6]
    vel[ab[:, 1]] = local[:, 6:]


def record_approach(vel: np.ndarray, cs: ContactSet, r: Rows) -> None:
    """The normal relative velocity of the points not touched yet this frame (what
    restitution bounces back once they take an impulse)."""
    rel = np.einsum("msj,mj->ms", r.jn, _gather(vel, cs.ab))
    cs.relative = np.where(cs.touched, cs.relative, rel)


def warm_start(vel: np.ndarray, cs: ContactSet, r: Rows) -> None:
    """Apply the accumulated impulses (from the last sub-step, or the last frame's contacts at
    the same place) before solving: resting contacts start where they ended. A sum, so one
    pass over every manifold at once."""
    if not len(cs):
        return
    m = len(cs)
    d = np.einsum("ms,msj->mj", cs.impulse[..., 0], r.mn) + \
        np.einsum("mt,mtj->mj", cs.impulse[..., 1:].reshape(m, -1), r.mt)
    scatter_add(vel, cs.ab[:, 0], d[:, :6])
    scatter_add(vel, cs.ab[:, 1], d[:, 6:])


def solve(vel: np.ndarray, cs: ContactSet, r: Rows, sc: Scales) -> None:
    """One Gauss-Seidel sweep, colour by colour: each manifold's normal impulses solved
    together (a block, falling back to point by point where one would pull), then friction."""
    for s, e in cs.colours:
        ab = cs.ab[s:e]
        local = _gather(vel, ab)
        _normal(local, cs, r, sc, s, e)
        _friction(local, cs, r, s, e)
        _scatter(vel, ab, local)
    cs.touched |= cs.impulse[..., 0] > 0.0


def _normal(local, cs, r, sc, s, e) -> None:
    """The normal impulses of manifolds s:e against their velocities ``local`` (updated).
    Points with no impulse that need none (separating, or closing a gap slower than it
    allows) stay out; manifolds without such points are solved as a block, the others (and
    blocks that would pull) as small complementarity problems (:func:`_active_set`)."""
    rel = np.einsum("msj,mj->ms", r.jn[s:e], local)
    old = cs.impulse[s:e, :, 0].copy()
    want = sc.mass[s:e] * rel + sc.bias[s:e]
    idle = cs.valid[s:e] & (old == 0.0) & (want >= 0.0)
    new = old - np.einsum("mij,mj->mi", cs.block[s:e], want) - sc.impulse[s:e] * old
    none = row_all(idle | ~cs.valid[s:e])
    new[none] = 0.0
    mixed = row_any(idle) & ~none
    pulling = row_any(new < 0.0) & ~none
    hard = np.nonzero(mixed | pulling)[0]
    if len(hard):
        new[hard], solved = _enumerated(cs, sc, hard + s, rel[hard], old[hard])
        rest = hard[~solved]
        if len(rest):
            start = np.where(mixed[rest, None], ~idle[rest], new[rest] >= 0.0)
            new[rest] = _active_set(cs, sc, rest + s, rel[rest], old[rest], start)
    local += np.einsum("ms,msj->mj", new - old, r.mn[s:e])
    cs.impulse[s:e, :, 0] = new


def _enumerated(cs, sc, m, rel, old) -> tuple[np.ndarray, np.ndarray]:
    """Normal impulses (g, S) of manifolds m whose block solution would pull at some points
    or that have points needing no impulse: the complementary solution (each point pushes
    with the others holding it exactly, or lets go and is left not approaching) found among
    every subset of its points at once, the largest that works (all four points of a face
    when they all push: the load stays shared symmetrically); where soft scaling leaves no
    subset exactly complementary, the one closest to it. Only for manifolds of at most W = 4
    points (the precomputed subset blocks); ``solved`` (g,) says which were."""
    w = cs.subsets.shape[2]
    valid = cs.valid[m]
    out = np.zeros_like(old)
    if valid.shape[1] > w:
        solved = ~valid[:, w:].any(axis=1)
        g = np.nonzero(solved)[0]
        if not len(g):
            return out, solved
        m, valid, old, rel = m[g], valid[g, :w], old[g, :w], rel[g, :w]
    else:
        solved, g = np.ones(len(m), bool), slice(None)
    masks, preference = blocks.subset_table(w)  # (C, w), (C,)
    v = valid[:, None]  # (g, 1, w)
    act = masks & v  # (g, C, w)
    allowed = ~row_any((masks & ~v).reshape(-1, w)).reshape(len(v), -1)  # subsets of the
    # valid points only
    mass, bias, imp = sc.mass[m, :w][:, None], sc.bias[m, :w], sc.impulse[m, :w]
    k = cs.coupling[m, :w, :w]
    o = old[:, None]
    # (x K = K x per subset row: the couplings are symmetric)
    rhs = mass * (rel[:, None] - np.matmul(np.where(act, 0.0, o), k)) + bias[:, None]
    new = np.where(act, o - np.matmul(cs.subsets[m], np.where(act, rhs, 0.0)[..., None])[..., 0]
                   - imp[:, None] * o, 0.0)
    after = mass * (rel[:, None] + np.matmul(new - o, k)) + bias[:, None]
    scale = 1e-6 * (np.abs(rel) + np.abs(bias) + 1e-3)[:, None]
    tiny = 1e-9 * row_max(np.abs(new).reshape(-1, w)).reshape(new.shape[:2] + (1,))
    # how far each subset's answer is from complementary: pull at its points (as the
    # velocity it makes) and approach at the others
    pull = np.where(act & (new < -tiny), -new, 0.0) * np.diagonal(k, axis1=1, axis2=2)[:, None]
    approach = np.where(v & ~act & (after < -scale), -after, 0.0)
    wrong = np.where(allowed, (pull + approach).sum(axis=2), np.inf)
    # the most preferred complementary subset, else the least wrong one (the first of equals)
    best = np.argmax(np.where(wrong == 0.0, preference, -wrong), axis=1)
    out[g, :w] = np.maximum(new[np.arange(len(best)), best], 0.0)
    return out, solved


def _active_set(cs, sc, m, rel, old, active) -> np.ndarray:
    """Normal impulses (g, S) of manifolds m whose block solution would pull at some points:
    a small linear complementarity problem per manifold, solved by principal pivoting. Points
    that would pull let go (impulse 0) and the others are solved together again; then, one
    point at a time (the first by index: Murty's rule), a point that pulls lets go or a
    let-go point that is left approaching takes part again. Symmetric loads stay symmetric
    (points let go together), which a point-by-point pass would not keep — a small body
    would spin up from the difference. Degenerate manifolds that do not settle within
    PIVOTS steps are finished point by point (:func:`_projected`)."""
    valid = cs.valid[m]
    active = active & valid
    out = np.zeros_like(old)
    todo = np.arange(len(m))  # manifolds not solved yet (rows of m)
    for _ in range(PIVOTS):
        mt, k, o = m[todo], cs.coupling[m[todo]], old[todo]
        act = active[todo]
        let_go = np.where(act, 0.0, -o)
        rhs = sc.mass[mt] * (rel[todo] + np.einsum("gij,gj->gi", k, let_go)) + sc.bias[mt]
        new = np.zeros_like(o)
        some = np.nonzero(act.any(axis=1))[0]  # (all let go: nothing to solve)
        if len(some):
            a_, o_ = act[some], o[some]
            inv = blocks.pinv(blocks.restricted(k[some], a_))
            new[some] = np.where(a_, o_ - np.einsum("gij,gj->gi", inv, np.where(a_, rhs[some], 0.0))
                                 - sc.impulse[mt[some]] * o_, 0.0)
        after = sc.mass[mt] * (rel[todo] + np.einsum("gij,gj->gi", k, new - o)) + sc.bias[mt]
        scale = 1e-6 * (np.abs(rel[todo]) + np.abs(sc.bias[mt]) + 1e-3)
        wrong = (act & (new < 0.0)) | (valid[todo] & ~act & (after < -scale))
        done = ~wrong.any(axis=1)
        out[todo] = new
        if done.all():
            return np.maximum(out, 0.0)
        left = np.nonzero(~done)[0]
        first = np.argmax(wrong[left], axis=1)
        active[todo[left], first] = ~active[todo[left], first]
        todo = todo[left]
    out[todo] = _projected(cs, sc, m[todo], rel[todo], old[todo])
    return np.maximum(out, 0.0)


def _projected(cs, sc, m, rel, old, sweeps: int = 4) -> np.ndarray:
    """Normal impulses (g, S) of manifolds m by projected Gauss-Seidel on their coupling:
    point by point, each clamped >= 0, ``sweeps`` times."""
    k, valid = cs.coupling[m], cs.valid[m]
    x = old.copy()
    for _ in range(sweeps):
        for i in range(valid.shape[1]):
            now = sc.mass[m, i] * (rel[:, i] + np.einsum("gj,gj->g", k[:, i], x - old)) + \
                sc.bias[m, i]
            step = x[:, i] - now / k[:, i, i] - sc.impulse[m, i] * x[:, i]
            x[:, i] = np.where(valid[:, i], np.maximum(step, 0.0), 0.0)
    return x


def _friction(local, cs, r, s, e) -> None:
    """Coulomb friction of every point of manifolds s:e: each point's two tangent impulses
    from the same velocities, shared over the manifold's points (symmetric, as the normal
    block), then clamped to its cone friction * normal impulse."""
    n = e - s
    rel = np.einsum("mtj,mj->mt", r.jt[s:e], local)
    old = cs.impulse[s:e, :, 1:].reshape(n, -1)
    new = (old - r.mass_t[s:e] * rel).reshape(n, -1, 2)
    limit = cs.friction[s:e] * cs.impulse[s:e, :, 0]
    norm = np.sqrt(np.einsum("msi,msi->ms", new, new))
    new *= np.minimum(1.0, limit / np.maximum(norm, 1e-300))[..., None]
    local += np.einsum("mt,mtj->mj", new.reshape(n, -1) - old, r.mt[s:e])
    cs.impulse[s:e, :, 1:] = new


def impacts(vel: np.ndarray, cs: ContactSet, r: Rows, separation: np.ndarray,
            h: float) -> None:
    """Impacts between two dynamic bodies this sub-step, processed as collisions before the
    contact solve (Guendelman, Bridson & Fedkiw's collision pass): points of bouncy bodies
    approaching faster than RESTITUTION_THRESHOLD and meeting within the sub-step leave at
    restitution times their approach speed now, one after another, colour by colour, until
    none is left approaching (at most IMPACT_PASSES sweeps). A ball swung into a row of
    touching balls then passes its speed along the row (Newton's cradle) instead of pushing
    the row as one. These impulses are the impact's, not the resting contact's: they are not
    kept for warm starting. Points so bounced do not bounce again at the sub-step's end."""
    live = (cs.restitution > 0.0) & cs.valid & ~cs.static[:, None]
    if not live.any():
        return
    for _ in range(IMPACT_PASSES):
        hit_any = False
        for s, e in cs.colours:
            m = np.nonzero(live[s:e].any(axis=1))[0] + s
            if not len(m):
                continue
            local = _gather(vel, cs.ab[m])
            for k in range(cs.valid.shape[1]):
                rel = np.einsum("mj,mj->m", r.jn[m, k], local)
                hit = live[m, k] & (rel < -RESTITUTION_THRESHOLD) & \
                    (separation[m, k] + h * rel <= 0.0)
                if not hit.any():
                    continue
                hit_any = True
                push = np.where(hit, -r.mass_n[m, k] * (1.0 + cs.restitution[m, k]) * rel, 0.0)
                local += push[:, None] * r.mn[m, k]
                cs.relative[m[hit], k] = 0.0
            _scatter(vel, cs.ab[m], local)
        if not hit_any:
            return


def restitution(vel: np.ndarray, cs: ContactSet, r: Rows) -> None:
    """Bounce: points that were approaching faster than RESTITUTION_THRESHOLD before their
    first impulse this frame and took one leave at restitution times that speed; each
    bounces once (its approach speed is then forgotten)."""
    bounce = (cs.restitution > 0.0) & (cs.relative < -RESTITUTION_THRESHOLD) & cs.touched
    if not bounce.any():
        return
    for s, e in cs.colours:
        m = np.nonzero(bounce[s:e].any(axis=1))[0] + s
        if not len(m):
            continue
        local = _gather(vel, cs.ab[m])
        for k in range(cs.valid.shape[1]):
            sel = bounce[m, k]
            rel = np.einsum("mj,mj->m", r.jn[m, k], local)
            old = cs.impulse[m, k, 0]
            new = np.where(sel, np.maximum(
                old - r.mass_n[m, k] * (rel + cs.restitution[m, k] * cs.relative[m, k]), 0.0),
                old)
            local += (new - old)[:, None] * r.mn[m, k]
            cs.impulse[m, k, 0] = new
        _scatter(vel, cs.ab[m], local)
    cs.relative[bounce] = 0.0
