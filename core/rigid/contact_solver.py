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
MAX_PUSH = 3.0  # [m/s] fastest overlap recovery
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
        friction, restitution: (k,) combined coefficients.
        relative: (k,) normal relative velocity when found [m/s] (for restitution).
        impulse: (k, 3) accumulated impulse along normal, t1, t2 [N s].
        total: (k,) sum of the normal impulses applied this frame (0: never touched).
        key: (k,) persistent ids (same features of the same bodies -> same key).
        static: (k,) True when one side does not move under impulses.
        groups: colour groups (index arrays).
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
    groups: list

    def __len__(self) -> int:
        return len(self.a)


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


def jacobians(cs: ContactSet, inv_mass: np.ndarray, inv_inertia: np.ndarray) -> Jacobians:
    """Constraint rows of every contact for this sub-step's world inverse inertias."""
    dirs = np.stack([cs.normal, cs.t1, cs.t2], axis=1)  # (k, 3, 3)
    ang_a = np.cross(cs.ra[:, None, :], dirs)
    ang_b = np.cross(cs.rb[:, None, :], dirs)
    wa = np.einsum("kij,kdj->kdi", inv_inertia[cs.a], ang_a)
    wb = np.einsum("kij,kdj->kdi", inv_inertia[cs.b], ang_b)
    k = (inv_mass[cs.a] + inv_mass[cs.b])[:, None] + np.einsum("kdi,kdi->kd", ang_a, wa) + \
        np.einsum("kdi,kdi->kd", ang_b, wb)
    return Jacobians(ang_a, ang_b, wa, wb, np.where(k > 0.0, 1.0 / np.maximum(k, 1e-300), 0.0))


def apply(v: np.ndarray, w: np.ndarray, cs: ContactSet, jac: Jacobians, idx: np.ndarray,
          d_impulse: np.ndarray, inv_mass: np.ndarray) -> None:
    """Apply impulse changes (len(idx), 3) along normal/t1/t2 of contacts ``idx``: body b
    gains, body a loses. Within a colour each dynamic body appears once, so plain indexed
    writes are exact; static rows get zero changes."""
    dirs = np.stack([cs.normal[idx], cs.t1[idx], cs.t2[idx]], axis=1)
    p = np.einsum("kd,kdi->ki", d_impulse, dirs)
    a, b = cs.a[idx], cs.b[idx]
    v[a] -= inv_mass[a][:, None] * p
    w[a] -= np.einsum("kd,kdi->ki", d_impulse, jac.wa[idx])
    v[b] += inv_mass[b][:, None] * p
    w[b] += np.einsum("kd,kdi->ki", d_impulse, jac.wb[idx])


def relative_velocity(v, w, cs: ContactSet, jac: Jacobians, idx: np.ndarray) -> np.ndarray:
    """(len(idx), 3) relative velocity of b's anchor against a's along normal, t1, t2."""
    a, b = cs.a[idx], cs.b[idx]
    dirs = np.stack([cs.normal[idx], cs.t1[idx], cs.t2[idx]], axis=1)
    return (np.einsum("kdi,ki->kd", dirs, v[b] - v[a])
            + np.einsum("kdi,ki->kd", jac.ang_b[idx], w[b])
            - np.einsum("kdi,ki->kd", jac.ang_a[idx], w[a]))


def solve(v, w, cs: ContactSet, jac: Jacobians, inv_mass, separation: np.ndarray, h: float,
          soft: Softness, static_soft: Softness, use_bias: bool) -> None:
    """One Gauss-Seidel sweep (colour by colour) over every contact: normal, then friction."""
    for idx in cs.groups:
        rel = relative_velocity(v, w, cs, jac, idx)
        s = separation[idx]
        stat = cs.static[idx]
        bias_rate = np.where(stat, static_soft.bias_rate, soft.bias_rate)
        m_scale = np.where(stat, static_soft.mass_scale, soft.mass_scale)
        i_scale = np.where(stat, static_soft.impulse_scale, soft.impulse_scale)
        speculative = s > 0.0
        if use_bias:  # a speculative point may close its gap, an overlap is pushed out softly
            bias = np.where(speculative, s / h, np.maximum(m_scale * bias_rate * s, -MAX_PUSH))
            m_scale = np.where(speculative, 1.0, m_scale)
            i_scale = np.where(speculative, 0.0, i_scale)
        else:  # relax: remove the push-out velocity, keep the speculative limit
            bias = np.where(speculative, s / h, 0.0)
            m_scale, i_scale = 1.0, 0.0
        acc = cs.impulse[idx]
        n_old = acc[:, 0]
        d_n = -jac.mass[idx, 0] * (m_scale * rel[:, 0] + bias) - i_scale * n_old
        n_new = np.maximum(n_old + d_n, 0.0)
        d = np.zeros((len(idx), 3))
        d[:, 0] = n_new - n_old
        cs.total[idx] += d[:, 0]
        # friction from the velocities the normal impulse leaves (its change is along n only)
        rel_t = rel[:, 1:] + _normal_effect(cs, jac, idx, d[:, 0], inv_mass)
        t_old = acc[:, 1:]
        t_new = t_old - jac.mass[idx, 1:] * rel_t
        limit = cs.friction[idx] * n_new
        norm = np.linalg.norm(t_new, axis=1)
        t_new *= np.where(norm > limit, limit / np.maximum(norm, 1e-300), 1.0)[:, None]
        d[:, 1:] = t_new - t_old
        cs.impulse[idx] = np.column_stack([n_new, t_new])
        apply(v, w, cs, jac, idx, d, inv_mass)


def _normal_effect(cs, jac, idx, d_n, inv_mass) -> np.ndarray:
    """Change of the tangential relative velocities (len(idx), 2) a normal impulse d_n makes."""
    a, b = cs.a[idx], cs.b[idx]
    n = cs.normal[idx]
    dv = ((inv_mass[a] + inv_mass[b]) * d_n)[:, None] * n
    dw_a = -d_n[:, None] * jac.wa[idx, 0]
    dw_b = d_n[:, None] * jac.wb[idx, 0]
    t = np.stack([cs.t1[idx], cs.t2[idx]], axis=1)
    return (np.einsum("kdi,ki->kd", t, dv) + np.einsum("kdi,ki->kd", jac.ang_b[idx, 1:], dw_b)
            - np.einsum("kdi,ki->kd", jac.ang_a[idx, 1:], dw_a))


def warm_start(v, w, cs: ContactSet, jac: Jacobians, inv_mass) -> None:
    """Apply the accumulated impulses (from the last sub-step, or the last frame's contacts
    with the same key) before solving: resting contacts start where they ended."""
    for idx in cs.groups:
        cs.total[idx] += cs.impulse[idx, 0]
        apply(v, w, cs, jac, idx, cs.impulse[idx], inv_mass)


def restitution(v, w, cs: ContactSet, jac: Jacobians, inv_mass) -> None:
    """Bounce: contacts that were approaching faster than RESTITUTION_THRESHOLD and took an
    impulse leave at restitution times that speed."""
    for idx in cs.groups:
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
        apply(v, w, cs, jac, sel, d, inv_mass)
