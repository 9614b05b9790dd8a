"""Points against colliders: continuous detection, bounce and resting contact, for any system's
point set (particles, spring-mesh vertices).

Each collider kind answers through its :class:`~.path.ColliderPath`: first hits of segments,
points to push out, surface points near points. The passes below are shared. A point's path over
a sub-step, x0 (at s0) -> x1 (at s1), is tested in the collider's frame at its own times, which
makes a moving collider a static one with the relative motion. The seed's "more complicated"
response follows: find the time of impact on that segment, reflect the velocity there
(v' = -k_r v_n + v_t, Coulomb friction on v_t, relative to the collider's surface velocity), then
move the remainder of the sub-step along v' — so a fast point can never tunnel.

Everything is vectorised over points; the only Python loops are over colliders and passes.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .contacts import Contacts
from .path import SKIN, ColliderPath

PASSES = 3  # a bounce's remaining motion may hit another collider: re-test up to this often


def reflect(u: np.ndarray, n: np.ndarray, restitution: float, friction: float,
            rest_speed: float) -> np.ndarray:
    """Velocity after a collision, relative to the surface: u' = -k_r u_n + u_t with Coulomb
    friction taking up to mu * |normal impulse| from u_t. A bounce slower than ``rest_speed``
    ends in contact (u_n' = 0) so resting particles do not jitter."""
    un = np.einsum("ij,ij->i", u, n)
    approaching = un < 0.0
    un_new = np.where(approaching, -restitution * un, un)
    un_new = np.where(approaching & (un_new < rest_speed), 0.0, un_new)
    impulse = np.where(approaching, un_new - un, 0.0)
    ut = u - un[:, None] * n
    speed = np.linalg.norm(ut, axis=1)
    keep = np.clip(1.0 - friction * impulse / np.where(speed > 1e-12, speed, np.inf), 0.0, 1.0)
    return ut * keep[:, None] + un_new[:, None] * n


def _first_hits(colliders, start, x, s_start, s_end):
    """Earliest collider entry of each segment start -> x: (collider index or -1, t, local
    normal, local hit point, surface element or -1)."""
    count = len(x)
    best_t = np.full(count, np.inf)
    best = np.full(count, -1)
    normals = np.zeros((count, 3))
    locals_ = np.zeros((count, 3))
    elements = np.full(count, -1, dtype=np.int64)
    for ci, col in enumerate(colliders):
        hits = col.first_hits(start, x, s_start, s_end)
        better = hits.t < best_t[hits.index]
        g = hits.index[better]
        best_t[g] = hits.t[better]
        best[g] = ci
        normals[g] = hits.normal[better]
        locals_[g] = hits.point[better]
        elements[g] = -1 if hits.element is None else hits.element[better]
    return best, best_t, normals, locals_, elements


def respond(colliders: list[ColliderPath], x0: np.ndarray, x1: np.ndarray, v0: np.ndarray,
            v1: np.ndarray, s0: float, s1: float, h: float, rest_speed: float) -> Response:
    """Continuous collision response for a sub-step [s0, s1] of the frame interval.

    Args:
        x0, v0: (n, 3) state before the sub-step; x1, v1: after integration (collision-free).
        h: sub-step length [s]. rest_speed: bounces slower than this become contact [m/s].

    Returns:
        The corrected positions and velocities, the number of collisions handled and each hit
        point's first collision as :class:`Contacts` (``point``: where it was placed, outside
        the surface, carried to the sub-step's end with the surface; ``impulse``: the normal
        velocity change the bounce gave it).
    """
    x, v = x1.copy(), v1.copy()
    first = _FirstHits(len(x))
    if not colliders or len(x) == 0:
        return Response(x, v, 0, first.contacts())
    start = x0.copy()
    s_start = np.full(len(x), float(s0))
    s_end = np.full(len(x), float(s1))
    v_start = v0.copy()
    hits = 0
    active = np.arange(len(x))  # pass 1 tests everyone; later passes only re-test the hit ones
    touched = []
    for _ in range(PASSES):
        best, best_t, normals, locals_, elements = _first_hits(
            colliders, start[active], x[active], s_start[active], s_end[active])
        if not (best >= 0).any():
            break
        for ci, col in enumerate(colliders):
            sub = np.nonzero(best == ci)[0]
            if len(sub) == 0:
                continue
            idx = active[sub]
            t = best_t[sub]
            s_hit = s_start[idx] + t * (s_end[idx] - s_start[idx])
            p_w, n_w = col.to_world(locals_[sub], normals[sub], s_hit)
            v_hit = v_start[idx] + t[:, None] * (v[idx] - v_start[idx])
            v_c = col.surface_velocity(locals_[sub], s_hit, elements[sub])
            u = reflect(v_hit - v_c, n_w, col.frame.restitution, col.frame.friction, rest_speed)
            # the forces keep acting for the rest of the sub-step after the impact
            dv_after = (1.0 - t)[:, None] * (v[idx] - v_start[idx])
            v_new = u + v_c + dv_after
            remaining = (1.0 - t) * (s_end[idx] - s_start[idx]) / max(s1 - s0, 1e-300) * h
            start[idx] = p_w + (SKIN + col.offset) * n_w
            v_start[idx] = v_new
            travel = v_new - 0.5 * dv_after
            if col.hits_end_surface:
                # the hit point lies on the surface as it is at the sub-step's END (a deforming
                # mesh): the restart is at that time, and the rest of the motion is relative to
                # that surface, or its own motion would be counted twice
                travel = travel - v_c
                s_start[idx] = s_end[idx]
            else:
                s_start[idx] = s_hit
            x[idx] = start[idx] + remaining[:, None] * travel
            v[idx] = v_new
            hits += len(idx)
            # where the surface carries the placed point by the sub-step's end (a deforming
            # mesh's hit point already lies on its end-of-step surface)
            end = start[idx] if col.hits_end_surface else start[idx] + remaining[:, None] * v_c
            first.note(idx, n_w, v_c, col, end, u - (v_hit - v_c))
        active = active[best >= 0]
        touched.append(active)
    if touched:
        moved = np.unique(np.concatenate(touched))
        xs, vs = x[moved], v[moved]
        hits += _push_out(colliders, xs, vs, s_end[moved], start[moved], s_start[moved])
        x[moved], v[moved] = xs, vs
    return Response(x, v, hits, first.contacts())


class Response(NamedTuple):
    """What :func:`respond` did to a sub-step's points."""

    x: np.ndarray
    v: np.ndarray
    count: int
    first: Contacts


_VECTORS = ("point", "normal", "surface_velocity")  # noted per hit, (k, 3) each
_SCALARS = ("friction", "restitution", "impulse")


class _FirstHits:
    """Each point's first collision in one :func:`respond` call."""

    def __init__(self, count: int):
        self.seen = np.zeros(count, dtype=bool)
        self.vectors = {k: np.zeros((count, 3)) for k in _VECTORS}
        self.scalars = {k: np.zeros(count) for k in _SCALARS}

    def note(self, idx, n_w, v_c, col, point, du) -> None:
        """Points ``idx`` hit ``col`` (normals n_w, surface velocity v_c) and were placed at
        ``point``; ``du`` is their velocity change relative to the surface."""
        new = ~self.seen[idx]
        i = idx[new]
        self.seen[i] = True
        for key, value in zip(_VECTORS, (point, n_w, v_c)):
            self.vectors[key][i] = value[new]
        self.scalars["friction"][i] = col.frame.friction
        self.scalars["restitution"][i] = col.frame.restitution
        self.scalars["impulse"][i] = np.einsum("ij,ij->i", du[new], n_w[new])

    def contacts(self) -> Contacts:
        idx = np.nonzero(self.seen)[0]
        v, s = ({k: a[idx] for k, a in table.items()} for table in (self.vectors, self.scalars))
        return Contacts.of(idx, v["point"], v["normal"], v["surface_velocity"], s["friction"],
                           s["restitution"], impulse=s["impulse"])


def _push_out(colliders: list[ColliderPath], x: np.ndarray, v: np.ndarray, s: np.ndarray,
              start: np.ndarray, s_start: np.ndarray) -> int:
    """Last resort after the passes: a collider that swept back over a particle's remaining
    path start (at s_start) -> x (at s) (fast rotation) leaves it inside, or past a thin mesh;
    move it to the surface and drop the approaching normal velocity. Modifies x and v in place;
    returns how many particles it moved."""
    moved = 0
    for col in colliders:
        surf = col.push_out(x, s, start, s_start)
        idx, n_w = surf.index, surf.normal
        if len(idx) == 0:
            continue
        x[idx] = surf.point + (SKIN + col.offset) * n_w
        un = np.einsum("ij,ij->i", v[idx] - surf.velocity, n_w)
        v[idx] -= np.minimum(un, 0.0)[:, None] * n_w
        moved += len(idx)
    return moved


def resting_contacts(colliders: list[ColliderPath], x: np.ndarray, v: np.ndarray, s: float,
                     rest_speed: float) -> Contacts:
    """Points resting on a collider at parameter s: within CONTACT_DISTANCE of its surface and
    not moving away faster than ``rest_speed`` (the nearest surface where several are)."""
    count = len(x)
    best_d = np.full(count, np.inf)
    point, normal, surf_v = np.zeros((count, 3)), np.zeros((count, 3)), np.zeros((count, 3))
    gap, mu, k_r = np.zeros(count), np.zeros(count), np.zeros(count)
    for col in colliders if count else ():
        surf = col.near_surface(x, s)
        d = np.abs(surf.gap)
        near = d < best_d[surf.index]
        un = np.einsum("ij,ij->i", v[surf.index] - surf.velocity, surf.normal)
        ok = near & (un < rest_speed)
        idx = surf.index[ok]
        best_d[idx] = d[ok]
        point[idx] = surf.point[ok]
        normal[idx] = surf.normal[ok]
        surf_v[idx] = surf.velocity[ok]
        gap[idx] = surf.gap[ok]
        mu[idx] = col.frame.friction
        k_r[idx] = col.frame.restitution
    idx = np.nonzero(np.isfinite(best_d))[0]
    return Contacts.of(idx, point[idx], normal[idx], surf_v[idx], mu[idx], k_r[idx],
                       depth=-gap[idx])
