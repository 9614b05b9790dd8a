"""Rigid bodies against Mesh colliders (any triangle mesh: a bowl, terrain, Suzanne).

Each nearby body offers its contact points — a box's or hull's corners, a sphere's centre, a
capsule's axis ends, with their radius — and the mesh's hierarchy answers the closest surface
point and signed distance of each (pseudo-normals), taken on the side of the mesh the body's
centre of mass is on (an open mesh has no inside, and its winding says nothing). A point
closer than its pair's margin becomes a contact along the surface normal facing the body; each
body keeps at most 4 per mesh (the widest support). Mesh features poking into a body's flat face between
its corners are not seen (a box on a sharp ridge rests on its corners' nearest surface).
"""
from __future__ import annotations

import numpy as np

from ..collision.build import build_bvh
from ..collision.distance import closest_points
from ..collision.mesh import TriangleMesh
from .collide import BOX_CORNERS, FEATURES, SPECULATIVE, Found, approach, reduce_manifolds
from .model import BOX, CAPSULE, HULL, SPHERE


class MeshCache:
    """Hierarchies of the frame's mesh colliders, kept between frames while a mesh's (scaled,
    local) vertices stay the same. One per solver."""

    def __init__(self):
        self._known: dict[str, tuple[bytes, object]] = {}

    def bvh(self, name: str, vertices: np.ndarray, triangles: np.ndarray):
        key = vertices.tobytes() + triangles.tobytes()
        known = self._known.get(name)
        if known is None or known[0] != key:
            mesh = TriangleMesh(vertices, triangles, name=name)
            known = (key, build_bvh(mesh, "aabb"))
            self._known[name] = known
        return known[1]


def _points(bodies, rot: np.ndarray, idx: np.ndarray):
    """(owner, feature, world point, radius) of the contact points of bodies ``idx``."""
    out = []
    centre = bodies.centres(rot)[idx]
    shape = bodies.shape[idx]
    sel = np.nonzero(shape == SPHERE)[0]
    out.append((idx[sel], np.zeros(len(sel), np.int64), centre[sel], bodies.radius[idx[sel]]))
    sel = np.nonzero(shape == CAPSULE)[0]
    for f, e in enumerate((-1.0, 1.0)):
        axis = rot[idx[sel], :, 2] * (e * bodies.half[idx[sel], 2])[:, None]
        out.append((idx[sel], np.full(len(sel), f), centre[sel] + axis, bodies.radius[idx[sel]]))
    sel = np.nonzero(shape == BOX)[0]
    if len(sel):
        local = BOX_CORNERS[None] * bodies.half[idx[sel], None, :]
        corners = centre[sel, None, :] + np.einsum("nij,ncj->nci", rot[idx[sel]], local)
        out.append((np.repeat(idx[sel], 8), np.tile(np.arange(8), len(sel)),
                    corners.reshape(-1, 3), np.zeros(8 * len(sel))))
    sel = np.nonzero(shape == HULL)[0]
    if len(sel):
        body = idx[sel]
        count = bodies.hull_count[body]
        owner = np.repeat(body, count)
        k = np.arange(len(owner)) - np.repeat(np.cumsum(count) - count, count)
        local = bodies.hull_points[np.repeat(bodies.hull_start[body], count) + k]
        out.append((owner, k, bodies.x[owner] + np.einsum("nij,nj->ni", rot[owner], local),
                    np.zeros(len(owner))))
    return tuple(np.concatenate(p) for p in zip(*out))


def _side(bvh, bodies, rot, g: int, near: np.ndarray, count: int) -> np.ndarray:
    """(count,) +1 or -1 per body: the side of the mesh its centre of mass is on (an open
    mesh has no inside: a body meets it from where it is, whatever the faces' winding)."""
    local = np.einsum("ji,nj->ni", rot[g], bodies.x[near] - bodies.x[g])
    sd = closest_points(bvh, local).signed_distance
    side = np.ones(count)
    side[near] = np.where(sd < 0.0, -1.0, 1.0)
    return side


def mesh_contacts(bodies, rot: np.ndarray, reach: np.ndarray, interval: float) -> Found:
    """Contacts of every dynamic body with every Mesh collider of the frame."""
    parts = []
    dyn = np.nonzero(bodies.dynamic)[0]
    for g, (bvh, lo, hi) in bodies.meshes.items():
        local = np.einsum("ji,nj->ni", rot[g], bodies.x[dyn] - bodies.x[g])  # R^T (x - x_g)
        grow = (bodies.bound[dyn] + reach[dyn] + reach[g] + SPECULATIVE)[:, None]
        near = dyn[((local + grow >= lo) & (local - grow <= hi)).all(axis=1)
                   & bodies.searched(dyn, g)]
        if not len(near):
            continue
        owner, feature, p, radius = _points(bodies, rot, near)
        margin = SPECULATIVE + reach[owner] + reach[g]
        lp = np.einsum("ji,nj->ni", rot[g], p - bodies.x[g])
        cp = closest_points(bvh, lp, max_distance=float((margin + radius).max()))
        side = _side(bvh, bodies, rot, g, near, len(bodies))[owner]
        found = cp.triangle >= 0
        sep = np.where(found, side * cp.signed_distance - radius, np.inf)
        keep = sep < margin
        owner, feature, sep = owner[keep], feature[keep], sep[keep]
        n_out = np.einsum("ij,nj->ni", rot[g], cp.normal[keep]) * side[keep, None]
        q = bodies.x[g] + np.einsum("ij,nj->ni", rot[g], cp.point[keep])
        point = q + 0.5 * sep[:, None] * n_out
        ahead = sep + interval * approach(bodies, owner, g, point, n_out)
        sel = reduce_manifolds(owner, point, np.minimum(sep, ahead))
        owner, feature, point, sep, n_out = owner[sel], feature[sel], point[sel], sep[sel], n_out[sel]
        key = (owner * len(bodies) + g) * FEATURES + feature
        parts.append(Found(owner, np.full(len(owner), g), point, -n_out, sep, key))
    return Found.join(parts)
