"""The analytic colliders' unit shapes in their local space (ground, bounded plane, sphere,
box; their extent grown by the thickness): closed-form segment entry, closest point, inside
tests and the corners and edges faces meet (:mod:`.analytic` moves them). Vectorised over
points."""
from __future__ import annotations

import numpy as np

from .path import Features


def shape_features(shape: str, e: np.ndarray) -> Features:
    """A sphere's centre (its radius the extent), a box's or a bounded plane's corners and
    edges (a plane of no thickness: its four), nothing of the ground."""
    if shape == "SPHERE":
        return Features.still(np.zeros((1, 3)), e[:1].copy(), np.zeros((0, 2, 3)))
    if shape == "HALF_SPACE":
        return Features.none()
    flat = shape == "PLANE" and e[2] == 0.0
    signs = np.array([(x, y, z) for z in ((0.0,) if flat else (-1.0, 1.0))
                      for y in (-1.0, 1.0) for x in (-1.0, 1.0)])
    corners = signs * e
    # corners differing in one sign share an edge
    differ = np.abs(signs[:, None, :] - signs[None, :, :]).astype(bool).sum(axis=2)
    i, j = np.nonzero(np.triu(differ == 1))
    return Features.still(corners, np.zeros(len(corners)), np.stack([corners[i], corners[j]], 1))


# --- shape geometry in local space -------------------------------------------------------------
# ``e`` (3,) is the shape's extent in local units, grown by the collider's thickness:
# HALF_SPACE: solid below z = e[2]; PLANE: the slab |z| <= e[2], |x| <= e[0], |y| <= e[1];
# SPHERE: radius e[0]; BOX: half extents e.

def inside(shape: str, l: np.ndarray, e: np.ndarray) -> np.ndarray:
    if shape == "HALF_SPACE":
        return l[:, 2] < e[2]
    if shape == "SPHERE":
        return np.einsum("ij,ij->i", l, l) < e[0] * e[0]
    if shape == "BOX":
        return np.all(np.abs(l) < e, axis=1)
    return np.zeros(len(l), dtype=bool)  # a plane is crossed, never entered


def closest(shape: str, l: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
        within = inside("BOX", l, e)
        p = np.clip(l, -e, e)
        gap = e - np.abs(l)
        axis = np.argmin(gap, axis=1)
        rows = np.arange(len(l))
        side = np.where(l[rows, axis] >= 0.0, 1.0, -1.0)
        p_in = l.copy()
        p_in[rows, axis] = side * e[axis]
        p = np.where(within[:, None], p_in, p)
        d = l - p
        dn = np.linalg.norm(d, axis=1, keepdims=True)
        n_out = d / np.where(dn > 1e-12, dn, 1.0)
        n_face = np.zeros_like(l)
        n_face[rows, axis] = side
        n = np.where(within[:, None] | (dn < 1e-12), n_face, n_out)
    return p, n, valid


def segment_hit(shape: str, l0: np.ndarray, l1: np.ndarray, e: np.ndarray):
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
        start_out = ~inside("BOX", l0, e)
        ok = start_out & ~outside_slab.any(axis=1) & (t_enter <= t_exit)
        ok &= (t_enter >= 0.0) & (t_enter <= 1.0)
        t = np.where(ok, t_enter, np.inf)
        rows = np.arange(count)
        n[rows, axis] = -np.sign(np.where(d[rows, axis] == 0.0, -1.0, d[rows, axis]))
    hit = np.isfinite(t)
    return hit, np.where(hit, t, 0.0), n
