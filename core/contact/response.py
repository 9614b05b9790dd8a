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

from ..transforms import rows_at, take
from .contacts import Contacts
from .path import (CONTACT_DISTANCE, SKIN, ColliderPath, SurfacePoints, cut_rows, same_times,
                   times_of)

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


def respond(colliders: list[ColliderPath], x0: np.ndarray, x1: np.ndarray, v0: np.ndarray,
            v1: np.ndarray, s0: float, s1: float, h: float, rest_speed: float,
            own: bool = False) -> Response:
    """Continuous collision response for a sub-step [s0, s1] of the frame interval.

    Up to :data:`PASSES` passes: find each remaining path's first hit, bounce the points that
    hit and restart their paths there; then push out whatever a collider still holds.

    Args:
        x0, v0: (n, 3) state before the sub-step; x1, v1: after integration (collision-free).
        h: sub-step length [s]. rest_speed: bounces slower than this become contact [m/s].
        own: x1 and v1 are the caller's to give away: when nothing hits they are returned as
            they are, not copied.

    Returns:
        The corrected positions and velocities, the number of collisions handled and each hit
        point's first collision as :class:`Contacts` (``point``: where it was placed, outside
        the surface, carried to the sub-step's end with the surface; ``impulse``: the normal
        velocity change the bounce gave it).
    """
    # pass 1 tests everyone (no gather) on the paths as given: most sub-steps hit nothing,
    # and where every collider is apart from every path, that is known without a test
    nearest = None if len(x1) == 0 or all(col.apart((x0, x1), s0, SKIN) for col in colliders) \
        else _nearest_hits(colliders, (x0, x1, same_times(s0, len(x1)),
                                       same_times(s1, len(x1))))
    if nearest is None:
        return (Response(x1, v1, 0, Contacts.none()) if own else
                Response(x1.copy(), v1.copy(), 0, Contacts.none()))
    first = _FirstHits(len(x1))
    remainder = _Remainder(x0, x1, v0, v1, s0, s1, h)
    active = None  # later passes only re-test the hit ones
    hits, touched = 0, []
    for pass_ in range(PASSES):
        if pass_:
            nearest = _nearest_hits(colliders, remainder.segments(active))
            if nearest is None:
                break
        hit = nearest.collider >= 0
        hits += _bounce(colliders, remainder, active, nearest, rest_speed, first)
        active = np.nonzero(hit)[0] if active is None else active[hit]
        touched.append(active)
    if touched:
        hits += remainder.push_out(colliders, np.unique(np.concatenate(touched)))
    return Response(remainder.x, remainder.v, hits, first.contacts())


class Response(NamedTuple):
    """What :func:`respond` did to a sub-step's points."""

    x: np.ndarray
    v: np.ndarray
    count: int
    first: Contacts


class _Remainder:
    """What is left of each point's path over the sub-step: from ``start`` (at parameter
    ``s_start``, velocity ``v_start``) to ``x`` (at ``s_end``, velocity ``v``), all (n, 3) or
    (n,). A bounce restarts a path at its hit point; the arrays are updated in place."""

    def __init__(self, x0, x1, v0, v1, s0: float, s1: float, h: float):
        self.x, self.v = x1.copy(), v1.copy()
        self.start = x0.copy()
        self.s_start = np.full(len(x1), float(s0))
        self.s_end = np.full(len(x1), float(s1))
        self.v_start = v0.copy()
        self.span = max(s1 - s0, 1e-300)  # the sub-step's parameter length, h [s] long
        self.h = h

    def segments(self, idx: np.ndarray | None):
        """Paths ``idx`` (None: all, without copying) as the segments the colliders test:
        start, end, s_start, s_end."""
        if idx is None:
            return self.start, self.x, self.s_start, self.s_end
        return self.start[idx], self.x[idx], self.s_start[idx], self.s_end[idx]

    def restart(self, col: ColliderPath, idx: np.ndarray, impact: _Impact) -> np.ndarray:
        """Restart paths ``idx`` at their impacts on ``col`` with the bounced velocity; returns
        where the surface carries each placed point by the sub-step's end."""
        t, v_c = impact.t, impact.surface_velocity
        # the forces keep acting for the rest of the sub-step after the impact
        dv_after = (1.0 - t)[:, None] * (self.v[idx] - self.v_start[idx])
        v_new = impact.reflected + v_c + dv_after
        remaining = (1.0 - t) * (self.s_end[idx] - self.s_start[idx]) / self.span * self.h
        self.start[idx] = impact.point + (SKIN + col.offset) * impact.normal
        self.v_start[idx] = v_new
        travel = v_new - 0.5 * dv_after
        if col.hits_end_surface:
            # the hit point lies on the surface as it is at the sub-step's END (a deforming
            # mesh): the restart is at that time, and the rest of the motion is relative to
            # that surface, or its own motion would be counted twice
            travel = travel - v_c
            self.s_start[idx] = self.s_end[idx]
        else:
            self.s_start[idx] = impact.s
        self.x[idx] = self.start[idx] + remaining[:, None] * travel
        self.v[idx] = v_new
        if col.hits_end_surface:  # the hit point already lies on the end-of-step surface
            return self.start[idx]
        return self.start[idx] + remaining[:, None] * v_c

    def push_out(self, colliders: list[ColliderPath], moved: np.ndarray) -> int:
        """:func:`_push_out` for the paths ``moved``; returns how many it moved."""
        xs, vs = self.x[moved], self.v[moved]
        count = _push_out(colliders, xs, vs, self.s_end[moved], self.start[moved],
                          self.s_start[moved])
        self.x[moved], self.v[moved] = xs, vs
        return count


class _Nearest(NamedTuple):
    """Each tested path's earliest collider entry, in that collider's local frame."""

    collider: np.ndarray  # (k,) index into the colliders, -1: no hit
    t: np.ndarray  # (k,) fraction of the remaining path before the hit (inf: no hit)
    normal: np.ndarray  # (k, 3) local unit normals
    point: np.ndarray  # (k, 3) local hit points
    element: np.ndarray  # (k,) int64 surface element hit, or -1

    def take(self, sub: np.ndarray) -> _Nearest:
        return _Nearest(*(a[sub] for a in self))


def _nearest_hits(colliders: list[ColliderPath], segments: tuple) -> _Nearest | None:
    """Earliest collider entry of each path of ``segments`` (start, end, s_start, s_end:
    :meth:`_Remainder.segments`); None when no path enters any collider."""
    start, x, s_start, s_end = segments
    count = len(x)
    nearest = None  # made at the first hit (most sub-steps have none)
    cuts = cut_rows(colliders, 0.0, start, x, times=(s_start, s_end))
    for ci, col in enumerate(colliders):
        rows = None if cuts is None else cuts[ci]
        if rows is None:
            hits = col.first_hits(start, x, s_start, s_end)
        elif len(rows):
            hits = col.first_hits(take(start, rows), take(x, rows), times_of(s_start, rows),
                                  times_of(s_end, rows)).of_rows(rows)
        else:
            continue
        if not len(hits.index):
            continue
        if nearest is None:
            nearest = _Nearest(np.full(count, -1), np.full(count, np.inf),
                               np.zeros((count, 3)), np.zeros((count, 3)),
                               np.full(count, -1, dtype=np.int64))
        better = hits.t < nearest.t[hits.index]
        g = hits.index[better]
        nearest.t[g] = hits.t[better]
        nearest.collider[g] = ci
        nearest.normal[g] = hits.normal[better]
        nearest.point[g] = hits.point[better]
        nearest.element[g] = -1 if hits.element is None else hits.element[better]
    return nearest


def _bounce(colliders: list[ColliderPath], remainder: _Remainder, active: np.ndarray | None,
            nearest: _Nearest, rest_speed: float, first: _FirstHits) -> int:
    """Bounce the active paths (None: all) that hit, collider by collider, and restart them at
    their hit points; returns how many bounced."""
    count = 0
    for ci, col in enumerate(colliders):
        sub = np.nonzero(nearest.collider == ci)[0]
        if len(sub) == 0:
            continue
        idx = sub if active is None else active[sub]
        impact = _impact(col, remainder, idx, nearest.take(sub), rest_speed)
        end = remainder.restart(col, idx, impact)
        first.note(idx, impact.normal, impact.surface_velocity, col, end,
                   impact.reflected - impact.approach, ci)
        count += len(idx)
    return count


class _Impact(NamedTuple):
    """Where and how k paths met one collider, in world space."""

    t: np.ndarray  # (k,) fraction of the remaining path before the hit
    s: np.ndarray  # (k,) frame-interval parameter of the hit
    point: np.ndarray  # (k, 3) hit points on the surface proper [m]
    normal: np.ndarray  # (k, 3) unit normals facing the side the points came from
    surface_velocity: np.ndarray  # (k, 3) the surface's velocity there [m/s]
    approach: np.ndarray  # (k, 3) the points' velocity at the hit, relative to the surface
    reflected: np.ndarray  # (k, 3) their velocity after the bounce, relative to the surface


def _impact(col: ColliderPath, remainder: _Remainder, idx: np.ndarray, hit: _Nearest,
            rest_speed: float) -> _Impact:
    """The impacts of paths ``idx`` on ``col`` (their nearest hits ``hit``) and the bounce."""
    t = hit.t
    s_hit = remainder.s_start[idx] + t * (remainder.s_end[idx] - remainder.s_start[idx])
    p_w, n_w = col.to_world(hit.point, hit.normal, s_hit)
    v_hit = remainder.v_start[idx] + t[:, None] * (remainder.v[idx] - remainder.v_start[idx])
    v_c = col.surface_velocity(hit.point, s_hit, hit.element)
    u_in = v_hit - v_c
    u = reflect(u_in, n_w, col.frame.restitution, col.frame.friction, rest_speed)
    return _Impact(t, s_hit, p_w, n_w, v_c, u_in, u)


_VECTORS = ("point", "normal", "surface_velocity")  # noted per hit, (k, 3) each
_SCALARS = ("friction", "restitution", "impulse")


class _FirstHits:
    """Each point's first collision in one :func:`respond` call."""

    def __init__(self, count: int):
        self.seen = np.zeros(count, dtype=bool)
        self.vectors = {k: np.zeros((count, 3)) for k in _VECTORS}
        self.scalars = {k: np.zeros(count) for k in _SCALARS}
        self.collider = np.full(count, -1, np.int64)

    def note(self, idx, n_w, v_c, col, point, du, which: int) -> None:
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
        self.collider[i] = which

    def contacts(self) -> Contacts:
        idx = np.nonzero(self.seen)[0]
        v, s = ({k: a[idx] for k, a in table.items()} for table in (self.vectors, self.scalars))
        return Contacts.of(idx, v["point"], v["normal"], v["surface_velocity"], s["friction"],
                           s["restitution"], impulse=s["impulse"], collider=self.collider[idx])


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
    found = []  # per collider: (its index, its SurfacePoints of the resting points)
    cuts = cut_rows(colliders, CONTACT_DISTANCE, x, s=s)
    for ci, col in enumerate(colliders if len(x) else ()):
        rows = None if cuts is None else cuts[ci]
        if rows is not None:
            if not len(rows):
                continue
            surf = col.near_surface(take(x, rows), s).of_rows(rows)
        elif col.apart((x,), s, CONTACT_DISTANCE):
            continue
        else:
            surf = col.near_surface(x, s)
        if surf.axis is not None:  # a still ground: the normal speed is one column
            un = rows_at(v, surf.index)[:, surf.axis[0]] * surf.axis[1]
        else:
            un = np.einsum("ij,ij->i", rows_at(v, surf.index) - surf.velocity, surf.normal)
        ok = np.nonzero(un < rest_speed)[0]
        if len(ok):
            found.append((ci, surf if len(ok) == len(un) else surf.take(ok)))
    if not found:
        return Contacts.none()
    which = np.concatenate([np.full(len(f.index), ci, np.int64) for ci, f in found])
    surf = SurfacePoints.joined([f for _, f in found])
    if len(found) > 1:  # a point near several surfaces rests on the nearest (the first tie)
        order = np.lexsort((np.abs(surf.gap), surf.index))
        first = np.ones(len(order), bool)
        first[1:] = surf.index[order[1:]] != surf.index[order[:-1]]
        keep = order[first]
        surf, which = surf.take(keep), which[keep]
    frames = [col.frame for col in colliders]
    if len(found) == 1:
        frame = frames[found[0][0]]
        mu, k_r = np.full(len(which), frame.friction), np.full(len(which), frame.restitution)
    else:
        mu = np.array([f.friction for f in frames])[which]
        k_r = np.array([f.restitution for f in frames])[which]
    return Contacts.of(surf.index, surf.point, surf.normal, surf.velocity, mu, k_r,
                       depth=-surf.gap, collider=which, axis=surf.axis)
