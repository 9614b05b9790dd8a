"""Particles against colliders: continuous detection, bounce and resting contact.

Each collider kind (analytic shapes here, triangle meshes in :mod:`.mesh_collider`) answers
through its :class:`~.collider_path.ColliderPath`: first hits of segments, points to push out,
surface near points. The passes below are shared. A particle's path over a sub-step, x0 (at s0)
-> x1 (at s1), is tested in the collider's frame at its own times, which makes a moving collider
a static one with the relative motion. The seed's "more complicated" response follows: find the
time of impact on that segment, reflect the velocity there (v' = -k_r v_n + v_t, Coulomb
friction on v_t, relative to the collider's surface velocity), then move the remainder of the
sub-step along v' — so a fast particle can never tunnel.

Everything is vectorised over particles; the only Python loops are over colliders and passes.
"""
from __future__ import annotations

import numpy as np

from ..transforms import inverse_affine
from .collider_path import CONTACT_DISTANCE, SKIN, ColliderPath, Hits, SurfacePoints
from .forces import ContactForce
from .mesh_collider import MeshPath
from .settings import ColliderFrame

__all__ = ["CONTACT_DISTANCE", "PASSES", "SKIN", "AnalyticPath", "ColliderPath", "MeshPath",
           "contacts", "reflect", "respond"]

PASSES = 3  # a bounce's remaining motion may hit another collider: re-test up to this often


class AnalyticPath(ColliderPath, shapes=("HALF_SPACE", "PLANE", "SPHERE", "BOX")):
    """A unit shape (see :class:`ColliderFrame`) grown by the collider's thickness.

    Attributes:
        extent: (3,) the shape's extent in local units, thickness included (see below).
    """

    def __init__(self, frame: ColliderFrame, frame_dt: float):
        super().__init__(frame, frame_dt)
        margin = frame.thickness * self.per_metre
        if frame.shape == "SPHERE":
            extent = np.full(3, 1.0 + frame.thickness * float(self.per_metre.mean()))
        elif frame.shape == "HALF_SPACE":
            extent = np.array([0.0, 0.0, margin[2]])
        else:  # PLANE: a slab of half-thickness margin; BOX: grown half extents
            extent = np.array([1.0 + margin[0], 1.0 + margin[1],
                               margin[2] if frame.shape == "PLANE" else 1.0 + margin[2]])
        self.extent = extent

    def first_hits(self, start, end, s_start, s_end) -> Hits:
        shape = self.frame.shape
        cand = self._segment_candidates(start, end, s_start, s_end)
        if cand is None:
            cand = np.arange(len(end))
        if len(cand) == 0:
            return Hits.none()
        l0 = self.to_local(start[cand], s_start[cand])
        l1 = self.to_local(end[cand], s_end[cand])
        hit, t, n_local = _segment_hit(shape, l0, l1, self.extent)
        l_hit = l0 + t[:, None] * (l1 - l0)
        # a collider that moved onto a particle: push it out to the nearest surface point
        stuck = ~hit & _inside(shape, l1, self.extent)
        if stuck.any():
            p, n_in, _ = _closest(shape, l1[stuck], self.extent)
            l_hit[stuck] = p
            n_local[stuck] = n_in
            t = np.where(stuck, 1.0, t)
            hit = hit | stuck
        return Hits(cand[hit], t[hit], n_local[hit], l_hit[hit])

    def push_out(self, x, s, start, s_start) -> SurfacePoints:
        l = self.to_local(x, s)
        inside = _inside(self.frame.shape, l, self.extent)
        if not inside.any():
            return SurfacePoints.none()
        idx = np.nonzero(inside)[0]
        p, n_local, _ = _closest(self.frame.shape, l[idx], self.extent)
        p_w, n_w = self.to_world(p, n_local, s[idx])
        gap = np.einsum("ij,ij->i", x[idx] - p_w, n_w)
        return SurfacePoints(idx, p_w, n_w, self.surface_velocity(p, s[idx]), gap)

    def near_surface(self, x, s) -> SurfacePoints:
        shape = self.frame.shape
        if shape in ("HALF_SPACE", "PLANE"):
            # cheap prefilter: world distance to the plane is local z / |grad z|
            inv = inverse_affine(self._at(s))
            z = self._local_z(x, s)
            gap = z - self.extent[2] if shape == "HALF_SPACE" else np.abs(z) - self.extent[2]
            cand = np.nonzero(np.abs(gap) < CONTACT_DISTANCE * np.linalg.norm(inv[2, :3]))[0]
        else:
            cand = np.arange(len(x))
        if len(cand) == 0:
            return SurfacePoints.none()
        l = self.to_local(x[cand], s)
        p, n_local, valid = _closest(shape, l, self.extent)
        p_w, n_w = self.to_world(p, n_local, s)
        d = np.einsum("ij,ij->i", x[cand] - p_w, n_w)
        near = np.nonzero(valid & (d > -CONTACT_DISTANCE) & (d < CONTACT_DISTANCE))[0]
        return SurfacePoints(cand[near], p_w[near], n_w[near],
                             self.surface_velocity(p[near], s), d[near])

    def _local_z(self, x: np.ndarray, s) -> np.ndarray:
        """Local z of points (the only coordinate planes need): one row of the inverse matrix."""
        inv = inverse_affine(self._at(s))
        if inv.ndim == 2:
            return x[:, 0] * inv[2, 0] + x[:, 1] * inv[2, 1] + x[:, 2] * inv[2, 2] + inv[2, 3]
        return np.einsum("nj,nj->n", inv[:, 2, :3], x) + inv[:, 2, 3]

    def _segment_candidates(self, start, end, s_start, s_end) -> np.ndarray | None:
        """Indices of segments that may hit a plane-like collider (cheap z test), or None when
        every segment must be tested (spheres, boxes)."""
        shape = self.frame.shape
        if shape not in ("HALF_SPACE", "PLANE"):
            return None
        z1 = self._local_z(end, s_end)
        level = self.extent[2]
        if shape == "HALF_SPACE":
            return np.nonzero(z1 < level)[0]
        z0 = self._local_z(start, s_start)
        return np.nonzero((z0 > level) & (z1 <= level) | (z0 < -level) & (z1 >= -level))[0]


# --- shape geometry in local space -------------------------------------------------------------
# ``e`` (3,) is the shape's extent in local units, grown by the collider's thickness:
# HALF_SPACE: solid below z = e[2]; PLANE: the slab |z| <= e[2], |x| <= e[0], |y| <= e[1];
# SPHERE: radius e[0]; BOX: half extents e.

def _inside(shape: str, l: np.ndarray, e: np.ndarray) -> np.ndarray:
    if shape == "HALF_SPACE":
        return l[:, 2] < e[2]
    if shape == "SPHERE":
        return np.einsum("ij,ij->i", l, l) < e[0] * e[0]
    if shape == "BOX":
        return np.all(np.abs(l) < e, axis=1)
    return np.zeros(len(l), dtype=bool)  # a plane is crossed, never entered


def _closest(shape: str, l: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest surface point, outward normal (local) and whether that point is on the surface
    proper (False for points off a bounded plane's edge)."""
    n = np.zeros_like(l)
    valid = np.ones(len(l), dtype=bool)
    if shape in ("HALF_SPACE", "PLANE"):
        side = np.ones(len(l)) if shape == "HALF_SPACE" else np.where(l[:, 2] >= 0.0, 1.0, -1.0)
        p = l.copy()
        p[:, 2] = side * e[2]
        n[:, 2] = side
        if shape == "PLANE":
            valid = np.all(np.abs(l[:, :2]) <= e[:2], axis=1)
    elif shape == "SPHERE":
        r = np.linalg.norm(l, axis=1, keepdims=True)
        n = np.where(r > 1e-12, l / np.where(r > 1e-12, r, 1.0), [0.0, 0.0, 1.0])
        p = n * e[0]
    else:  # BOX: outside -> clamp; inside -> nearest face
        inside = _inside("BOX", l, e)
        p = np.clip(l, -e, e)
        gap = e - np.abs(l)
        axis = np.argmin(gap, axis=1)
        rows = np.arange(len(l))
        side = np.where(l[rows, axis] >= 0.0, 1.0, -1.0)
        p_in = l.copy()
        p_in[rows, axis] = side * e[axis]
        p = np.where(inside[:, None], p_in, p)
        d = l - p
        dn = np.linalg.norm(d, axis=1, keepdims=True)
        n_out = d / np.where(dn > 1e-12, dn, 1.0)
        n_face = np.zeros_like(l)
        n_face[rows, axis] = side
        n = np.where(inside[:, None] | (dn < 1e-12), n_face, n_out)
    return p, n, valid


def _segment_hit(shape: str, l0: np.ndarray, l1: np.ndarray, e: np.ndarray):
    """First entry of segments l0 -> l1 into the shape: (hit mask, t in [0, 1], local normal)."""
    d = l1 - l0
    count = len(l0)
    t = np.full(count, np.inf)
    n = np.zeros_like(l0)
    if shape in ("HALF_SPACE", "PLANE"):
        z0, z1 = l0[:, 2], l1[:, 2]
        top = (z0 >= e[2]) & (z1 < e[2]) if shape == "HALF_SPACE" else (z0 > e[2]) & (z1 <= e[2])
        bottom = np.zeros(count, bool) if shape == "HALF_SPACE" else (z0 < -e[2]) & (z1 >= -e[2])
        level = np.where(top, e[2], -e[2])
        cross = top | bottom
        denom = np.where(cross, z0 - z1, 1.0)
        tt = np.where(cross, (z0 - level) / denom, np.inf)
        if shape == "PLANE":
            p = l0 + tt.clip(0, 1)[:, None] * d
            cross &= np.all(np.abs(p[:, :2]) <= e[:2], axis=1)
        t = np.where(cross, tt, np.inf)
        n[:, 2] = np.where(bottom, -1.0, 1.0)
    elif shape == "SPHERE":
        a = np.einsum("ij,ij->i", d, d)
        b = np.einsum("ij,ij->i", l0, d)
        c = np.einsum("ij,ij->i", l0, l0) - e[0] * e[0]
        disc = b * b - a * c
        ok = (c >= 0.0) & (disc >= 0.0) & (a > 0.0)
        tt = (-b - np.sqrt(np.where(ok, disc, 0.0))) / np.where(ok, a, 1.0)
        ok &= (tt >= 0.0) & (tt <= 1.0)
        t = np.where(ok, tt, np.inf)
        p = l0 + np.where(ok, tt, 0.0)[:, None] * d
        n = p / np.maximum(np.linalg.norm(p, axis=1, keepdims=True), 1e-12)
    else:  # BOX, slab method
        with np.errstate(divide="ignore", invalid="ignore"):
            ta = (-e - l0) / d
            tb = (e - l0) / d
        parallel = d == 0.0
        outside_slab = parallel & (np.abs(l0) > e)
        lo = np.where(parallel, -np.inf, np.minimum(ta, tb))
        hi = np.where(parallel, np.inf, np.maximum(ta, tb))
        t_enter = lo.max(axis=1)
        t_exit = hi.min(axis=1)
        axis = lo.argmax(axis=1)
        start_out = ~_inside("BOX", l0, e)
        ok = start_out & ~outside_slab.any(axis=1) & (t_enter <= t_exit)
        ok &= (t_enter >= 0.0) & (t_enter <= 1.0)
        t = np.where(ok, t_enter, np.inf)
        rows = np.arange(count)
        n[rows, axis] = -np.sign(np.where(d[rows, axis] == 0.0, -1.0, d[rows, axis]))
    hit = np.isfinite(t)
    return hit, np.where(hit, t, 0.0), n


# --- passes ------------------------------------------------------------------------------------

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
            v1: np.ndarray, s0: float, s1: float, h: float, rest_speed: float,
            record: dict | None = None):
    """Continuous collision response for a sub-step [s0, s1] of the frame interval.

    Args:
        x0, v0: (n, 3) state before the sub-step; x1, v1: after integration (collision-free).
        h: sub-step length [s]. rest_speed: bounces slower than this become contact [m/s].
        record: if given, filled with each hit particle's first collision as arrays:
            ``index``, ``normal`` (world), ``surface_velocity``, ``restitution``, ``friction``,
            and ``landing``, the point it was placed at (outside the surface) carried to the
            sub-step's end with the surface's velocity.

    Returns:
        (x, v, hits): corrected positions and velocities, and the number of collisions handled.
    """
    x, v = x1.copy(), v1.copy()
    first = None if record is None else _FirstHits(len(x))
    if not colliders or len(x) == 0:
        if first is not None:
            first.into(record)
        return x, v, 0
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
            if getattr(col, "hits_end_surface", False):
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
            if first is not None:
                # where the surface carries the placed point by the sub-step's end (a deforming
                # mesh's hit point already lies on its end-of-step surface)
                end = start[idx] if getattr(col, "hits_end_surface", False) \
                    else start[idx] + remaining[:, None] * v_c
                first.note(idx, n_w, v_c, col, end)
        active = active[best >= 0]
        touched.append(active)
    if touched:
        moved = np.unique(np.concatenate(touched))
        xs, vs = x[moved], v[moved]
        hits += _push_out(colliders, xs, vs, s_end[moved], start[moved], s_start[moved])
        x[moved], v[moved] = xs, vs
    if first is not None:
        first.into(record)
    return x, v, hits


_VECTORS = ("normal", "surface_velocity", "landing")  # recorded per hit, (k, 3) each


class _FirstHits:
    """Each particle's first collision in one :func:`respond` call (for ``record``)."""

    def __init__(self, count: int):
        self.seen = np.zeros(count, dtype=bool)
        self.vectors = {k: np.zeros((count, 3)) for k in _VECTORS}
        self.scalars = {k: np.zeros(count) for k in ("restitution", "friction")}

    def note(self, idx, n_w, v_c, col, landing) -> None:
        new = ~self.seen[idx]
        i = idx[new]
        self.seen[i] = True
        for key, value in zip(_VECTORS, (n_w, v_c, landing)):
            self.vectors[key][i] = value[new]
        self.scalars["restitution"][i] = col.frame.restitution
        self.scalars["friction"][i] = col.frame.friction

    def into(self, record: dict) -> None:
        idx = np.nonzero(self.seen)[0]
        record["index"] = idx
        for table in (self.vectors, self.scalars):
            record.update({k: v[idx] for k, v in table.items()})


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


def contacts(colliders: list[ColliderPath], x: np.ndarray, v: np.ndarray, s: float,
             rest_speed: float, h: float) -> ContactForce:
    """Particles resting on a collider at parameter s: within CONTACT_DISTANCE of its surface
    and not moving away faster than ``rest_speed``."""
    count = len(x)
    best_d = np.full(count, np.inf)
    normal = np.zeros((count, 3))
    surf_v = np.zeros((count, 3))
    mu = np.zeros(count)
    k_r = np.zeros(count)
    for col in colliders if count else ():
        surf = col.near_surface(x, s)
        d = np.abs(surf.gap)
        near = d < best_d[surf.index]
        un = np.einsum("ij,ij->i", v[surf.index] - surf.velocity, surf.normal)
        ok = near & (un < rest_speed)
        idx = surf.index[ok]
        best_d[idx] = d[ok]
        normal[idx] = surf.normal[ok]
        surf_v[idx] = surf.velocity[ok]
        mu[idx] = col.frame.friction
        k_r[idx] = col.frame.restitution
    idx = np.nonzero(np.isfinite(best_d))[0]
    return ContactForce(idx, normal[idx], surf_v[idx], mu[idx], h, k_r[idx])
