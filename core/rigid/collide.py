"""Which bodies touch, once per frame: broad phase -> narrow phase by shape pair -> contact
points with persistent keys (for warm starting).

Bodies here are every body the contact solver sees (:class:`Bodies`): the rigid bodies, then
the colliders of the frame as bodies that impulses do not move. Pairs are found by a uniform
grid over boxes swept by each body's motion over the frame (its pairs kept between searches
while every box stays within the one they were found for: :class:`KeptPairs`); a half-space
(the ground) is tested against every body directly. Each pair gets a speculative margin that
covers how far the two can approach: at their relative velocity within the frame, or by their
own motions until the next search, whichever is more (a half-space's or a mesh's pairs: by
the body's own motion within the frame), so the solver sees contacts before they happen.
Pairs whose bounding spheres are further apart than their margin skip the narrow phase.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import cross
from ..collision.broadphase import UniformGrid
from ..collision.kept import KeptPairs
from . import narrow, narrow_hull
from . import quaternion as quat
from .hull_shape import HullSet
from .model import BOX, CAPSULE, HULL, MESH, SPHERE

HALF_SPACE = 5  # a collider's code: the solid below a plane (normal = local +Z)
# MESH (model.MESH): a triangle mesh, a Mesh collider or a concave Mesh body (:mod:`.mesh_contacts`)
SPECULATIVE = 0.02  # [m] contacts this far apart are always reported
FEATURES = 4096  # feature ids per pair in a contact key
SUPPORT_TOLERANCE = 0.25 * SPECULATIVE  # [m] see reduce_manifolds
# candidate pairs kept between searches (:class:`KeptPairs`) are found for swept boxes grown by
# this fraction of the bodies' median bound radius (a search then reads them for the fresh bodies
# only, so a wider margin costs little and saves grid searches)
KEPT_PAIRS_FRACTION = 0.25
BOX_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)],
                       dtype=np.float64)


@dataclass
class Bodies:
    """The contact solver's bodies for one frame (N of them): rigid bodies, then colliders.

    Attributes:
        shape: (N,) codes (model.SHAPES order, HALF_SPACE for a ground). half: (N, 3) box half
            extents, capsule half length in [2]. radius: (N,). offset: (N, 3) shape centre
            from the centre of mass, local. x: (N, 3) centre of mass. q: (N, 4) orientation.
        v, w: (N, 3) velocities [m/s], [rad/s]. bound: (N,) radius of the shape about x.
        dynamic: (N,) moved by impulses. friction, restitution: (N,).
        hull_points, hull_start, hull_count: HULL vertices (local, from the centre of mass).
        name: (N,) names (messages).
        hulls: the HULL bodies' hulls (faces, edges), hull_index: (N,) each body's hull in it
            (-1: not a hull).
    """

    shape: np.ndarray
    half: np.ndarray
    radius: np.ndarray
    offset: np.ndarray
    x: np.ndarray
    q: np.ndarray
    v: np.ndarray
    w: np.ndarray
    bound: np.ndarray
    dynamic: np.ndarray
    friction: np.ndarray
    restitution: np.ndarray
    hull_points: np.ndarray
    hull_start: np.ndarray
    hull_count: np.ndarray
    name: tuple
    hulls: HullSet | None = None
    hull_index: np.ndarray | None = None
    meshes: dict | None = None  # row of a Mesh collider or body -> MeshShape
    sleeping: np.ndarray | None = None  # (N,) resting bodies: found only to be woken
    moving: np.ndarray | None = None  # (N,) bodies that move on their own this frame
    fresh: np.ndarray | None = None  # (N,) bodies whose contacts are searched (None: all)
    excluded: np.ndarray | None = None  # keys lo * N + hi of pairs that never collide (joined)

    def __len__(self) -> int:
        return len(self.shape)

    def searched(self, rows: np.ndarray, other: int | np.ndarray) -> np.ndarray:
        """Which of the pairs (rows, other) have contacts to search: one side is fresh."""
        if self.fresh is None:
            return np.ones(len(rows), bool)
        return self.fresh[rows] | self.fresh[other]

    def centres(self, rotations: np.ndarray) -> np.ndarray:
        """(N, 3) world centres of the shapes."""
        return self.x + np.einsum("nij,nj->ni", rotations, self.offset)


@dataclass(frozen=True)
class Found:
    """Contact points between bodies a and b (k): world point midway between the surfaces,
    unit normal from a to b, separation (< 0: overlap) and persistent key."""

    a: np.ndarray
    b: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    separation: np.ndarray
    key: np.ndarray

    @classmethod
    def join(cls, parts: list[Found]) -> Found:
        if not parts:
            z = np.zeros(0, np.int64)
            return cls(z, z, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), z)
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in
                     ("a", "b", "point", "normal", "separation", "key")))


def find_contacts(bodies: Bodies, frame_dt: float, gravity: np.ndarray,
                  interval: float | None = None, kept: KeptPairs | None = None) -> Found:
    """Every contact point for the next ``frame_dt`` [s] (speculative ones included);
    ``interval`` [s]: until the next search (which points of a body against a surface matter
    most: :func:`reduce_manifolds`), the whole duration when not given. Two bodies' margin
    covers how far they can approach each other: at their relative velocity within
    ``frame_dt``, or by their own motions until the next search (one of them stopped by a
    third), whichever is more; bodies falling side by side do not approach. ``kept``: the
    candidate pairs of earlier searches (:func:`kept_pairs`), read again while every body's
    swept box stays within the one they were found for."""
    rot = quat.to_matrix(bodies.q)
    reach = _reach(bodies, frame_dt, gravity)
    ground = bodies.shape == HALF_SPACE
    interval = frame_dt if interval is None else interval
    parts = [_half_spaces(bodies, rot, reach, ground, interval)]
    if bodies.meshes:
        from .mesh_contacts import mesh_contacts  # it builds on this module

        parts.append(mesh_contacts(bodies, rot, reach, interval))
    i, j = _candidate_pairs(bodies, reach, ground | (bodies.shape == MESH), kept)
    excluded = bodies.excluded is not None and len(bodies.excluded)
    if excluded:  # pairs that do not collide (joined) skip the narrow phase
        keep = ~np.isin(np.minimum(i, j) * len(bodies) + np.maximum(i, j), bodies.excluded)
        i, j = i[keep], j[keep]
    margin = SPECULATIVE + _closing(bodies, i, j, frame_dt, interval, gravity)
    # pairs whose bounding spheres are further apart than their margin have no point within it
    gap = np.linalg.norm(bodies.x[i] - bodies.x[j], axis=1) - bodies.bound[i] - bodies.bound[j]
    near = np.flatnonzero(gap <= margin)
    i, j, margin = i[near], j[near], margin[near]
    centre = bodies.centres(rot)
    for kinds, run in _KINDS:
        sel = _of_kind(bodies.shape, i, j, kinds)
        if len(sel[0]):
            a, b, at = sel
            parts.append(_keyed(bodies, a, b, run(bodies, rot, centre, a, b, margin[at])))
    found = Found.join(parts)
    if excluded:  # (the ground's and meshes' contacts)
        pair = np.minimum(found.a, found.b) * len(bodies) + np.maximum(found.a, found.b)
        keep = ~np.isin(pair, bodies.excluded)
        found = Found(*(getattr(found, f)[keep] for f in
                        ("a", "b", "point", "normal", "separation", "key")))
    return found


def _reach(bodies: Bodies, frame_dt: float, gravity: np.ndarray) -> np.ndarray:
    """(N,) how far any point of each body can move within the frame [m] (an upper bound)."""
    speed = np.linalg.norm(bodies.v, axis=1) + np.linalg.norm(bodies.w, axis=1) * bodies.bound
    fall = np.where(bodies.dynamic, 0.5 * float(np.linalg.norm(gravity)) * frame_dt ** 2, 0.0)
    return speed * frame_dt + fall


def _closing(bodies: Bodies, i: np.ndarray, j: np.ndarray, frame_dt: float, interval: float,
             gravity: np.ndarray) -> np.ndarray:
    """(k,) how far bodies i and j can approach each other [m]: within ``frame_dt`` at their
    relative velocity (turning counts at their bounds; gravity counts when one of them falls
    and the other does not: a collider, a kinematic or a sleeping body), or within
    ``interval`` by their own motions, whichever is more."""
    v = np.linalg.norm(bodies.v[i] - bodies.v[j], axis=1)
    turn = np.linalg.norm(bodies.w[i], axis=1) * bodies.bound[i] + \
        np.linalg.norm(bodies.w[j], axis=1) * bodies.bound[j]
    fall = np.where(bodies.dynamic[i] != bodies.dynamic[j],
                    0.5 * float(np.linalg.norm(gravity)) * frame_dt ** 2, 0.0)
    own = _reach(bodies, interval, gravity)
    return np.maximum((v + turn) * frame_dt + fall, own[i] + own[j])


def kept_pairs() -> KeptPairs:
    """Candidate pairs to keep between searches (:func:`find_contacts`)."""
    return KeptPairs(_grid_pairs, within=True)


def _grid_pairs(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(i, j) the overlapping boxes, i < j, sorted (a uniform grid)."""
    pairs = UniformGrid().pairs(lo, hi)
    return pairs[:, 0], pairs[:, 1]


def _candidate_pairs(bodies: Bodies, reach: np.ndarray, ground: np.ndarray,
                     kept: KeptPairs | None = None):
    """(i, j) index pairs of bodies whose swept boxes overlap, at least one of them dynamic
    (the same pairs, in the same order, whether read from ``kept`` or searched)."""
    idx = np.nonzero(~ground)[0]
    if len(idx) < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    grow = (bodies.bound + reach + 0.5 * SPECULATIVE)[idx, None]
    lo, hi = bodies.x[idx] - grow, bodies.x[idx] + grow
    if kept is None:
        i, j = _grid_pairs(lo, hi)
    else:
        i, j = kept.pairs(KEPT_PAIRS_FRACTION * float(np.median(bodies.bound[idx])), lo, hi,
                          only=None if bodies.fresh is None else bodies.fresh[idx])
    i, j = idx[i], idx[j]
    keep = bodies.dynamic[i] | bodies.dynamic[j]
    if bodies.sleeping is not None:  # a moving kinematic body or collider wakes sleepers
        wake = bodies.sleeping & ~bodies.dynamic
        keep |= (wake[i] & bodies.moving[j]) | (bodies.moving[i] & wake[j])
    keep &= bodies.searched(i, j)
    return i[keep], j[keep]


def _of_kind(shape, i, j, kinds):
    """Pairs whose shapes are ``kinds`` (in either order), ordered as ``kinds``; and their
    positions in (i, j)."""
    ka, kb = kinds
    direct = (shape[i] == ka) & (shape[j] == kb)
    flipped = (shape[i] == kb) & (shape[j] == ka) & (ka != kb)
    at = np.nonzero(direct | flipped)[0]
    a = np.where(direct[at], i[at], j[at])
    b = np.where(direct[at], j[at], i[at])
    return a, b, at


def _keyed(bodies: Bodies, a, b, pc: narrow.PairContacts) -> Found:
    pa, pb = a[pc.pair], b[pc.pair]
    lo, hi = np.minimum(pa, pb), np.maximum(pa, pb)
    key = (lo * len(bodies) + hi) * FEATURES + pc.feature
    return Found(pa, pb, pc.point, pc.normal, pc.separation, key)


def _sphere_sphere(bd, rot, c, a, b, m):
    return narrow.sphere_sphere(c[a], bd.radius[a], c[b], bd.radius[b], m)


def _sphere_box(bd, rot, c, a, b, m):
    return narrow.sphere_box(c[a], bd.radius[a], c[b], rot[b], bd.half[b], m)


def _box_box(bd, rot, c, a, b, m):
    return narrow.box_box(c[a], rot[a], bd.half[a], c[b], rot[b], bd.half[b], m)


def _capsule_sphere(bd, rot, c, a, b, m):  # a: sphere, b: capsule -> call with the capsule first
    return narrow.capsule_sphere(c[b], rot[b], bd.radius[b], bd.half[b, 2], c[a],
                                 bd.radius[a], m).swapped()


def _capsule_box(bd, rot, c, a, b, m):  # a: box, b: capsule
    return narrow.capsule_box(c[b], rot[b], bd.radius[b], bd.half[b, 2], c[a], rot[a],
                              bd.half[a], m).swapped()


def _capsule_capsule(bd, rot, c, a, b, m):
    return narrow.capsule_capsule(c[a], rot[a], bd.radius[a], bd.half[a, 2], c[b], rot[b],
                                  bd.radius[b], bd.half[b, 2], m)


def _sphere_hull(bd, rot, c, a, b, m):  # a: sphere, b: hull (at its centre of mass)
    return narrow_hull.hull_sphere(bd.hulls, bd.x[b], rot[b], c[a], bd.radius[a], m,
                                   index=bd.hull_index[b]).swapped()


def _box_hull(bd, rot, c, a, b, m):
    return narrow_hull.hull_box(bd.hulls, bd.x[b], rot[b], c[a], rot[a], bd.half[a], m,
                                index=bd.hull_index[b]).swapped()


def _capsule_hull(bd, rot, c, a, b, m):
    return narrow_hull.hull_capsule(bd.hulls, bd.x[b], rot[b], c[a], rot[a], bd.radius[a],
                                    bd.half[a, 2], m, index=bd.hull_index[b]).swapped()


def _hull_hull(bd, rot, c, a, b, m):
    return narrow_hull.hull_hull(bd.hulls, bd.x[a], rot[a], bd.hulls, bd.x[b], rot[b], m,
                                 index_a=bd.hull_index[a], index_b=bd.hull_index[b])


_KINDS = (((SPHERE, SPHERE), _sphere_sphere), ((SPHERE, BOX), _sphere_box),
          ((BOX, BOX), _box_box), ((SPHERE, CAPSULE), _capsule_sphere),
          ((BOX, CAPSULE), _capsule_box), ((CAPSULE, CAPSULE), _capsule_capsule),
          ((SPHERE, HULL), _sphere_hull), ((BOX, HULL), _box_hull),
          ((CAPSULE, HULL), _capsule_hull), ((HULL, HULL), _hull_hull))


# --- half-spaces: every body's support points below the plane -----------------------------------

def support_points(bodies: Bodies, rot: np.ndarray, idx: np.ndarray, normal: np.ndarray):
    """World points of bodies ``idx`` that can touch a plane with outward ``normal`` (3,):
    (owner (p,), feature (p,), point (p, 3)) — a sphere's lowest point, the corners of a box's
    face turned most towards the plane (a box turning fast onto a face keeps the corners it
    is about to land on), a capsule's two lowest cap points, a hull's vertices."""
    out = []
    centre = bodies.centres(rot)[idx]
    shape = bodies.shape[idx]
    for code in (SPHERE, CAPSULE):
        sel = np.nonzero(shape == code)[0]
        ends = (0,) if code == SPHERE else (-1, 1)
        for f, e in enumerate(ends):
            axis = rot[idx[sel], :, 2] * (e * bodies.half[idx[sel], 2])[:, None]
            p = centre[sel] + axis - bodies.radius[idx[sel], None] * normal
            out.append((idx[sel], np.full(len(sel), f), p))
    sel = np.nonzero(shape == BOX)[0]
    if len(sel):  # the corners of the face turned most towards the plane (the deepest is one)
        facing = np.einsum("nji,j->ni", rot[idx[sel]], normal)  # the normal in box axes
        axis = np.argmax(np.abs(facing), axis=1)
        side = -np.sign(facing[np.arange(len(sel)), axis])
        face = BOX_CORNERS.T[axis] == side[:, None]  # (boxes, 8): 4 corners each
        owner, corner = np.nonzero(face)
        local = BOX_CORNERS[corner] * bodies.half[idx[sel][owner]]
        out.append((idx[sel][owner], corner, centre[sel][owner]
                    + np.einsum("nij,nj->ni", rot[idx[sel][owner]], local)))
    sel = np.nonzero((shape == HULL) | (shape == MESH))[0]  # a Mesh body: its hull's vertices
    if len(sel):
        body = idx[sel]
        count = bodies.hull_count[body]
        owner = np.repeat(body, count)
        first = np.repeat(bodies.hull_start[body], count)
        k = np.arange(len(owner)) - np.repeat(np.cumsum(count) - count, count)
        local = bodies.hull_points[first + k]
        out.append((owner, k, bodies.x[owner] + np.einsum("nij,nj->ni", rot[owner], local)))
    if not out:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3))
    return tuple(np.concatenate(parts) for parts in zip(*out))


def _half_spaces(bodies: Bodies, rot: np.ndarray, reach: np.ndarray, ground: np.ndarray,
                 interval: float) -> Found:
    """Contacts of every dynamic body with every half-space collider."""
    parts = []
    dyn = np.nonzero(bodies.dynamic & ~ground)[0]
    for g in np.nonzero(ground)[0]:
        n = rot[g, :, 2]
        height = (bodies.x[dyn] - bodies.x[g]) @ n
        near = dyn[(height - bodies.bound[dyn] < SPECULATIVE + reach[dyn] + reach[g])
                   & bodies.searched(dyn, g)]
        owner, feature, p = support_points(bodies, rot, near, n)
        sep = (p - bodies.x[g]) @ n - bodies.radius[g]  # radius: the collider's thickness
        margin = SPECULATIVE + reach[owner] + reach[g]
        keep = sep < margin
        owner, feature, p, sep = owner[keep], feature[keep], p[keep], sep[keep]
        ahead = sep + interval * approach(bodies, owner, g, p, n)
        sel = reduce_manifolds(owner, p, np.minimum(sep, ahead))
        owner, feature, p, sep = owner[sel], feature[sel], p[sel], sep[sel]
        point = p - 0.5 * sep[:, None] * n
        key = (owner * len(bodies) + g) * FEATURES + feature
        parts.append(Found(owner, np.full(len(owner), g), point,
                           np.broadcast_to(-n, (len(owner), 3)).copy(), sep, key))
    return Found.join(parts)


def approach(bodies: Bodies, owner: np.ndarray, other, p: np.ndarray,
             n: np.ndarray) -> np.ndarray:
    """(k,) speed [m/s] at which points p (k, 3) of bodies ``owner`` move along the outward
    normals n (3,) or (k, 3) of body ``other``'s surface (one body, or one per point) (< 0:
    into it)."""
    def velocity(rows):
        return bodies.v[rows] + cross(bodies.w[rows], p - bodies.x[rows])
    return np.einsum("ki,ki->k", velocity(owner) - velocity(np.broadcast_to(other, owner.shape)),
                     np.broadcast_to(n, p.shape))


def reduce_manifolds(owner: np.ndarray, p: np.ndarray, sep: np.ndarray) -> np.ndarray:
    """Indices keeping at most 4 points per owner (a hull's many vertices on the ground): the
    deepest, the farthest from it, the farthest from their line, and the farthest on the
    other side of that line, among the points within SUPPORT_TOLERANCE of the deepest — the
    widest support with the deepest point in it. ``sep`` [m] ranks the points: pass the
    least separation expected until the next search."""
    if not len(owner):
        return np.zeros(0, np.int64)
    order = np.argsort(owner, kind="stable")
    uniq, first, count = np.unique(owner[order], return_index=True, return_counts=True)
    if count.max() <= 4:
        return order
    slot = np.arange(len(order)) - np.repeat(first, count)
    idx = np.full((len(uniq), int(count.max())), -1, np.int64)
    idx[np.repeat(np.arange(len(uniq)), count), slot] = order
    valid = idx >= 0
    rank = np.where(valid, sep[np.where(valid, idx, 0)], np.inf)
    # the support: points about as deep as the deepest (a ring's lowest row, not the wider row
    # above it: a manifold of points that do not touch lets the body sink to them)
    valid &= rank <= rank.min(axis=1, keepdims=True) + SUPPORT_TOLERANCE
    q = p[np.where(valid, idx, 0)]
    rows = np.arange(len(uniq))
    pick = [np.argmin(rank, axis=1)]
    far = np.linalg.norm(q - q[rows, pick[0]][:, None], axis=2)
    pick.append(np.argmax(np.where(valid, far, -1.0), axis=1))
    axis = q[rows, pick[1]] - q[rows, pick[0]]
    side = cross(axis[:, None, :], q - q[rows, pick[0]][:, None])
    ref = side[rows, np.argmax(np.where(valid, np.linalg.norm(side, axis=2), -1.0), axis=1)]
    signed = np.einsum("gki,gi->gk", side, ref)
    pick.append(np.argmax(np.where(valid, signed, -np.inf), axis=1))
    pick.append(np.argmin(np.where(valid, signed, np.inf), axis=1))
    chosen = np.unique(np.stack([idx[rows, k] for k in pick], axis=1).ravel())
    return chosen[chosen >= 0]
