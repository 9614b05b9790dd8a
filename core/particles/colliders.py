"""Particles against analytic colliders: continuous detection, bounce and resting contact.

Each collider is a unit shape in its object's local space (see :class:`ColliderFrame`) moved by an
interpolated world transform. A particle's path over a sub-step, x0 (at s0) -> x1 (at s1), is
mapped into the collider's frame at its own times, l0 = M(s0)^-1 x0 and l1 = M(s1)^-1 x1, which
makes a moving collider a static one with the relative motion. The seed's "more complicated"
response follows: find the time of impact on that segment, reflect the velocity there
(v' = -k_r v_n + v_t, Coulomb friction on v_t, relative to the collider's surface velocity),
then move the remainder of the sub-step along v' — so a fast particle can never tunnel.

Everything is vectorised over particles; the only Python loops are over colliders and passes.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import (TransformPath, inverse3, inverse_affine, norm_rows, transform_points,
                          transform_vectors)
from .forces import ContactForce
from .settings import ColliderFrame

SKIN = 1e-4  # [m] particles are placed this far outside a surface after a hit
CONTACT_DISTANCE = 1e-3  # [m] closer than this (and not separating) counts as resting contact
PASSES = 3  # a bounce's remaining motion may hit another collider: re-test up to this often


@dataclass
class ColliderPath:
    """One collider during one frame interval, with its motion path."""

    frame: ColliderFrame
    path: TransformPath
    frame_dt: float

    extent: np.ndarray | None = None

    @classmethod
    def of(cls, frame: ColliderFrame, frame_dt: float) -> "ColliderPath":
        path = TransformPath(frame.matrix0, frame.matrix1, frame.matrices)
        # local units per world metre along each local axis (rows of the inverse matrix)
        per_metre = np.linalg.norm(inverse_affine(path.m0)[:3, :3], axis=1)
        margin = frame.thickness * per_metre
        if frame.shape == "SPHERE":
            extent = np.full(3, 1.0 + frame.thickness * float(per_metre.mean()))
        elif frame.shape == "HALF_SPACE":
            extent = np.array([0.0, 0.0, margin[2]])
        else:  # PLANE: a slab of half-thickness margin; BOX: grown half extents
            extent = np.array([1.0 + margin[0], 1.0 + margin[1],
                               margin[2] if frame.shape == "PLANE" else 1.0 + margin[2]])
        return cls(frame, path, frame_dt, extent)

    def _at(self, s) -> np.ndarray:
        """The matrix at ``s``: one (4, 4) when s is a scalar or the same for every particle
        (the common case, far cheaper), else (n, 4, 4)."""
        s = np.asarray(s, dtype=np.float64)
        if self.path.static:
            return self.path.m0
        if s.ndim == 0 or (len(s) and s.min() == s.max()):
            return self.path.matrices(float(s.flat[0]) if s.size else 0.0)
        return self.path.matrices(s)

    def to_local(self, x: np.ndarray, s) -> np.ndarray:
        return transform_points(inverse_affine(self._at(s)), x)

    def to_world(self, l: np.ndarray, n_local: np.ndarray, s):
        """World points and unit normals of local points/normals at parameters s."""
        m = self._at(s)
        lin = m[..., :3, :3]
        p = transform_points(m, l)
        n = transform_vectors(np.swapaxes(inverse3(lin), -1, -2), n_local)  # inverse-transpose
        n /= norm_rows(n)[:, None]
        return p, n

    def surface_velocity(self, l: np.ndarray, s) -> np.ndarray:
        if self.path.static:
            return np.zeros_like(l)
        return self.path.point_velocities(l, np.broadcast_to(np.asarray(s, float), len(l)),
                                          self.frame_dt)


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


def _local_z(col: ColliderPath, x: np.ndarray, s) -> np.ndarray:
    """Local z of points (the only coordinate planes need): one row of the inverse matrix."""
    inv = inverse_affine(col._at(s))
    if inv.ndim == 2:
        return x[:, 0] * inv[2, 0] + x[:, 1] * inv[2, 1] + x[:, 2] * inv[2, 2] + inv[2, 3]
    return np.einsum("nj,nj->n", inv[:, 2, :3], x) + inv[:, 2, 3]


def _segment_candidates(col: ColliderPath, start, end, s_start, s_end) -> np.ndarray | None:
    """Indices of segments that may hit a plane-like collider (cheap z test), or None when
    every segment must be tested (spheres, boxes)."""
    shape = col.frame.shape
    if shape not in ("HALF_SPACE", "PLANE"):
        return None
    z1 = _local_z(col, end, s_end)
    level = col.extent[2]
    if shape == "HALF_SPACE":
        return np.nonzero(z1 < level)[0]
    z0 = _local_z(col, start, s_start)
    return np.nonzero((z0 > level) & (z1 <= level) | (z0 < -level) & (z1 >= -level))[0]


def _first_hits(colliders, start, x, s_start, s_end):
    """Earliest collider entry of each segment start -> x: (collider index or -1, t, local
    normal, local hit point)."""
    count = len(x)
    best_t = np.full(count, np.inf)
    best = np.full(count, -1)
    normals = np.zeros((count, 3))
    locals_ = np.zeros((count, 3))
    for ci, col in enumerate(colliders):
        cand = _segment_candidates(col, start, x, s_start, s_end)
        if cand is None:
            cand = np.arange(count)
        if len(cand) == 0:
            continue
        l0 = col.to_local(start[cand], s_start[cand])
        l1 = col.to_local(x[cand], s_end[cand])
        hit, t, n_local = _segment_hit(col.frame.shape, l0, l1, col.extent)
        l_hit = l0 + t[:, None] * (l1 - l0)
        # a collider that moved onto a particle: push it out to the nearest surface point
        stuck = ~hit & _inside(col.frame.shape, l1, col.extent)
        if stuck.any():
            p, n_in, _ = _closest(col.frame.shape, l1[stuck], col.extent)
            l_hit[stuck] = p
            n_local[stuck] = n_in
            t = np.where(stuck, 1.0, t)
            hit = hit | stuck
        better = hit & (t < best_t[cand])
        g = cand[better]
        best_t[g] = t[better]
        best[g] = ci
        normals[g] = n_local[better]
        locals_[g] = l_hit[better]
    return best, best_t, normals, locals_


def respond(colliders: list[ColliderPath], x0: np.ndarray, x1: np.ndarray, v0: np.ndarray,
            v1: np.ndarray, s0: float, s1: float, h: float, rest_speed: float):
    """Continuous collision response for a sub-step [s0, s1] of the frame interval.

    Args:
        x0, v0: (n, 3) state before the sub-step; x1, v1: after integration (collision-free).
        h: sub-step length [s]. rest_speed: bounces slower than this become contact [m/s].

    Returns:
        (x, v, hits): corrected positions and velocities, and the number of collisions handled.
    """
    x, v = x1.copy(), v1.copy()
    if not colliders or len(x) == 0:
        return x, v, 0
    start = x0.copy()
    s_start = np.full(len(x), float(s0))
    s_end = np.full(len(x), float(s1))
    v_start = v0.copy()
    hits = 0
    active = np.arange(len(x))  # pass 1 tests everyone; later passes only re-test the hit ones
    touched = []
    for _ in range(PASSES):
        best, best_t, normals, locals_ = _first_hits(
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
            v_c = col.surface_velocity(locals_[sub], s_hit)
            u = reflect(v_hit - v_c, n_w, col.frame.restitution, col.frame.friction, rest_speed)
            # the forces keep acting for the rest of the sub-step after the impact
            dv_after = (1.0 - t)[:, None] * (v[idx] - v_start[idx])
            v_new = u + v_c + dv_after
            remaining = (1.0 - t) * (s_end[idx] - s_start[idx]) / max(s1 - s0, 1e-300) * h
            start[idx] = p_w + SKIN * n_w
            s_start[idx] = s_hit
            v_start[idx] = v_new
            x[idx] = start[idx] + remaining[:, None] * (v_new - 0.5 * dv_after)
            v[idx] = v_new
            hits += len(idx)
        active = active[best >= 0]
        touched.append(active)
    if touched:
        moved = np.unique(np.concatenate(touched))
        xs, vs = x[moved], v[moved]
        hits += _push_out(colliders, xs, vs, s_end[moved])
        x[moved], v[moved] = xs, vs
    return x, v, hits


def _push_out(colliders: list[ColliderPath], x: np.ndarray, v: np.ndarray,
              s: np.ndarray) -> int:
    """Last resort after the passes: a collider that swept back over a particle's remaining
    path (fast rotation) leaves it inside; move it to the surface and drop the approaching
    normal velocity. Modifies x and v in place; returns how many particles it moved."""
    moved = 0
    for col in colliders:
        l = col.to_local(x, s)
        inside = _inside(col.frame.shape, l, col.extent)
        if not inside.any():
            continue
        idx = np.nonzero(inside)[0]
        p, n_local, _ = _closest(col.frame.shape, l[idx], col.extent)
        p_w, n_w = col.to_world(p, n_local, s[idx])
        x[idx] = p_w + SKIN * n_w
        rel = v[idx] - col.surface_velocity(p, s[idx])
        un = np.einsum("ij,ij->i", rel, n_w)
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
    for col in colliders if count else ():
        if col.frame.shape in ("HALF_SPACE", "PLANE"):
            # cheap prefilter: world distance to the plane is local z / |grad z|
            inv = inverse_affine(col._at(s))
            z = _local_z(col, x, s)
            gap = z - col.extent[2] if col.frame.shape == "HALF_SPACE" else np.abs(z) - col.extent[2]
            cand = np.nonzero(np.abs(gap) < CONTACT_DISTANCE * np.linalg.norm(inv[2, :3]))[0]
        else:
            cand = np.arange(count)
        if len(cand) == 0:
            continue
        sv = np.full(len(cand), float(s))
        l = col.to_local(x[cand], s)
        p, n_local, valid = _closest(col.frame.shape, l, col.extent)
        p_w, n_w = col.to_world(p, n_local, s)
        d = np.einsum("ij,ij->i", x[cand] - p_w, n_w)
        near = valid & (d > -CONTACT_DISTANCE) & (d < CONTACT_DISTANCE) & (np.abs(d) < best_d[cand])
        if not near.any():
            continue
        sub = np.nonzero(near)[0]
        vc = col.surface_velocity(p[sub], sv[sub])
        un = np.einsum("ij,ij->i", v[cand[sub]] - vc, n_w[sub])
        ok = un < rest_speed
        sub, vc = sub[ok], vc[ok]
        idx = cand[sub]
        best_d[idx] = np.abs(d[sub])
        normal[idx] = n_w[sub]
        surf_v[idx] = vc
        mu[idx] = col.frame.friction
    idx = np.nonzero(np.isfinite(best_d))[0]
    return ContactForce(idx, normal[idx], surf_v[idx], mu[idx], h)
