"""Contact points of convex hulls with hulls, boxes, spheres and capsules, vectorised over pairs.

Hull against hull (a box is a hull of 8 corners) is a separating-axis test in A's frame over
both hulls' face normals and the cross products of edge pairs whose arcs cross on the Gauss
map (Gregorius, GDC 2013): those pairs, and only they, span faces of the Minkowski difference,
so no other edge axis can be best, and their separation is one dot product. The arc test runs
on every edge pair as four batched matrix products, the rest on the few survivors; hulls are
therefore not capped. Pairs are grouped by that cost (e_A e_B within a factor of two share a
batch padded to its largest, at most ``BATCH_TESTS`` tests), so a big hull pads no small one.

A face axis wins unless an edge axis beats both by ``AXIS_TOL_REL`` x the pair's size; B's face
is the reference only if it beats A's by as much (in that band: the larger face), so resting
contact does not flicker. Face contact: the incident face (most opposed to the reference normal)
clipped against the reference face's side planes (Sutherland-Hodgman, one pass per plane); of
the points below ``margin`` at most 4 stay: the deepest, the farthest from it, the two spanning
the largest areas either side. Edge contact: one point between the edges' closest points.
Overlapping, separations are exact to within the axis tolerance (the least-penetration
direction of two polyhedra is a face or edge-pair axis); apart, they are lower bounds of the
distance: speculative points may come early, never late. Spheres, and capsules whose core is
outside the hull, use exact closest points. Feature ids hash the touching features into
[0, FEATURE_COUNT), distinct within a pair.
"""
from __future__ import annotations

import numpy as np

from ..transforms import cross
from .hull_shape import HullBatch, HullSet, HullShape
from .narrow_base import FEATURE_COUNT as FEATURES
from .narrow_base import PairContacts, as_margin, closest_segments, local, world

AXIS_TOL_REL = 1e-3  # preference for face axes and for A as reference, x (radius A + radius B)
PARALLEL_REL = 1e-6  # edges this close to parallel (sine of the angle) give no edge axis
SPREAD_REL = 1e-5  # clipped points closer than this x size count as one when keeping 4
FACE_ALIGN = 0.9995  # capsules: a closest direction this close to a face normal -> 2 points
CORE_WIDTH = 0.1 * SPREAD_REL  # a capsule's core as a box this thin (relative), points merge
BATCH_TESTS = 1 << 21  # edge pairs per batch (each test array is 8 bytes x this)


def hull_hull(hulls_a, x_a, rot_a, hulls_b, x_b, rot_b, margin=0.0, *, index_a=None,
              index_b=None) -> PairContacts:
    """Contacts of k pairs of hulls.

    Args:
        hulls_a, hulls_b: a :class:`HullShape` (every pair) or a :class:`HullSet`.
        x_a, x_b: (k, 3) world positions of the hulls' local origins [m].
        rot_a, rot_b: (k, 3, 3) rotations (local -> world, column vectors).
        margin: (k,) or scalar [m]: points with separation below it are reported.
        index_a, index_b: (k,) which hull of the set each pair uses (not for a HullShape).

    Returns:
        The pairs' contact points, normals from A towards B.
    """
    set_a, ia = _as_set(hulls_a, index_a, len(x_a))
    set_b, ib = _as_set(hulls_b, index_b, len(x_b))
    cost = set_a.hull_edge_count[ia] * set_b.hull_edge_count[ib]
    return _world(x_a, rot_a, *_batched(cost, margin, lambda s: (
        set_a.batch(ia[s]), _in_frame(set_b.batch(ib[s]), x_a[s], rot_a[s], x_b[s], rot_b[s]))))


def hull_box(hulls, x, rot, c_box, rot_box, half, margin=0.0, *, index=None) -> PairContacts:
    """Contacts of k hulls (A; see :func:`hull_hull`) with boxes (B): centres c_box (k, 3)
    [m], rotations rot_box (k, 3, 3), half extents half (k, 3) [m]."""
    set_a, ia = _as_set(hulls, index, len(x))
    half = np.asarray(half, dtype=np.float64).reshape(-1, 3)
    return _world(x, rot, *_batched(set_a.hull_edge_count[ia] * 12, margin, lambda s: (
        set_a.batch(ia[s]), _in_frame(HullBatch.boxes(half[s]), x[s], rot[s], c_box[s],
                                      rot_box[s]))))


def hull_sphere(hulls, x, rot, c_sphere, radius, margin=0.0, *, index=None) -> PairContacts:
    """Contacts of k hulls (A; see :func:`hull_hull`) with spheres (B) of centres (k, 3) [m]
    and radii (k,) [m]: one point at the hull surface point nearest the centre (the nearest
    face's when the centre is inside)."""
    set_a, ia = _as_set(hulls, index, len(x))
    dist, q, n, kind, ident = set_a.batch(ia).closest(local(rot, c_sphere - x))
    sep = dist - np.broadcast_to(radius, (len(ia),))
    pair = np.nonzero(sep < as_margin(margin, len(ia)))[0]
    return _world(x, rot, pair, (q + 0.5 * sep[:, None] * n)[pair], n[pair], sep[pair],
                  _code(kind[pair], ident[pair]))


def hull_capsule(hulls, x, rot, c_cap, rot_cap, radius, half_length, margin=0.0, *,
                 index=None) -> PairContacts:
    """Contacts of k hulls (A; see :func:`hull_hull`) with capsules (B) of centres (k, 3) [m],
    rotations (k, 3, 3) (axis: local Z), radii (k,) [m] and half lengths (k,) [m] between the
    cap centres; up to 2 points (a capsule lying along a face). Exact closest points while
    the core segment is outside the hull; when it pierces the hull, the core as a box of
    ``CORE_WIDTH`` x its size across, as hull against hull."""
    set_a, ia = _as_set(hulls, index, len(x))
    k = len(ia)
    h, radius, margin = set_a.batch(ia), np.broadcast_to(radius, (k,)), as_margin(margin, k)
    half = np.stack([np.zeros(k), np.zeros(k), np.broadcast_to(half_length, (k,))], axis=1)
    axis = local(rot, rot_cap[:, :, 2] * half[:, 2:])
    half[:, :2] = CORE_WIDTH * (half[:, 2:] + radius[:, None])
    p0 = local(rot, c_cap - x) - axis
    deep = h.crosses(p0, 2.0 * axis)
    i, j = np.nonzero(deep)[0], np.nonzero(~deep)[0]
    core = _in_frame(HullBatch.boxes(half[i]), x[i], rot[i], c_cap[i], rot_cap[i])
    pd, qd, nd, sd, fd = _polytopes(h.rows(i), core, margin[i] + radius[i])
    rd = radius[i][pd]  # the core's surface is the segment: move out to the capsule's
    parts = zip((i[pd], qd - 0.5 * rd[:, None] * nd, nd, sd - rd, fd),
                _segment_apart(h.rows(j), p0[j], 2.0 * axis[j], radius[j], margin[j], j))
    return _world(x, rot, *(np.concatenate(p) for p in parts))


# --- batching and frames ---------------------------------------------------------------------

def _as_set(hulls, index, k: int) -> tuple[HullSet, np.ndarray]:
    if isinstance(hulls, HullShape):
        hulls = HullSet.from_shapes([hulls])
    if index is None:
        if hulls.hull_count != 1:
            raise ValueError(f"a set of {hulls.hull_count} hulls needs an index per pair")
        return hulls, np.zeros(k, np.int64)
    return hulls, np.asarray(index, dtype=np.int64).reshape(k)


def _world(x, rot, pair, point, normal, sep, feature) -> PairContacts:
    """PairContacts, by pair, from points and normals in the frames (x, rot) of their pairs."""
    o = np.argsort(pair, kind="stable")
    p, r = pair[o].astype(np.int64), rot[pair[o]]
    return PairContacts(p, world(r, point[o]) + x[p], world(r, normal[o]), sep[o],
                        feature[o].astype(np.int64))


def _in_frame(b: HullBatch, x_a, rot_a, x_b, rot_b) -> HullBatch:
    """Hulls b, placed at (x_b, rot_b), in the frames (x_a, rot_a)."""
    return b.transformed(np.einsum("kji,kjl->kil", rot_a, rot_b), local(rot_a, x_b - x_a))


def _batched(cost: np.ndarray, margin, batch):
    """:func:`_polytopes` over groups of pairs of similar cost (within a factor of two), each
    cut into batches of at most ``BATCH_TESTS`` edge-pair tests; ``batch(rows)`` gives the
    rows' hulls (A, and B in A's frame). Returns (pair, point, normal, sep, feature)."""
    margin = as_margin(margin, len(cost))
    group = np.ceil(np.log2(np.maximum(cost, 1))).astype(np.int64)
    parts = [(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0),
              np.zeros(0, np.int64))]
    for g in np.unique(group):
        members = np.nonzero(group == g)[0]
        size = max(1, BATCH_TESTS // int(cost[members].max()))
        for s in range(0, len(members), size):
            sel = members[s:s + size]
            pair, *rest = _polytopes(*batch(sel), margin[sel])
            parts.append((sel[pair], *rest))
    return tuple(np.concatenate(p) for p in zip(*parts))


def _code(*parts) -> np.ndarray:
    """Hash of integer arrays into [0, FEATURES)."""
    h = np.zeros(np.broadcast(*parts).shape, np.int64)
    for p in parts:
        h = (h * 1031 + np.asarray(p, dtype=np.int64) + 7) % 1_000_003
    return h % FEATURES


# --- polytope against polytope (both in A's frame) ---------------------------------------------

def _polytopes(a: HullBatch, b: HullBatch, margin: np.ndarray):
    """Contacts of each row's hulls a and b (in a's frame): (pair, point, normal, sep,
    feature) with normals from a towards b, points in a's frame."""
    scale = a.radius + b.radius
    sa, fa = _face_query(a, b)
    sb, fb = _face_query(b, a)
    se, ea, eb, axis = np.full(len(sa), -np.inf), 0 * fa, 0 * fb, 0.0 * a.centre
    near = np.nonzero(np.maximum(sa, sb) < margin)[0]  # a face axis separates the others
    se[near], ea[near], eb[near], axis[near] = _edge_query(a.rows(near), b.rows(near))
    live = np.maximum(np.maximum(sa, sb), se) < margin
    tol = AXIS_TOL_REL * scale
    edge = live & (se > np.maximum(sa, sb) + tol)
    bigger = _area(b, fb) > _area(a, fa)
    ref_b = live & ~edge & ((sb > sa + tol) | ((sb >= sa - tol) & bigger))
    parts = []
    for ref, face, inc, rows, sign in ((a, fa, b, live & ~edge & ~ref_b, 1.0),
                                       (b, fb, a, ref_b, -1.0)):
        i = np.nonzero(rows)[0]
        pair, point, normal, sep, feature = _face_contacts(
            ref.rows(i), face[i], inc.rows(i), margin[i], scale[i])
        parts.append((i[pair], point, sign * normal, sep, feature))
    i = np.nonzero(edge)[0]
    parts.append((i, *_edge_contacts(a.rows(i), b.rows(i), ea[i], eb[i], axis[i], se[i])))
    return tuple(np.concatenate(p) for p in zip(*parts))


def _face_query(a: HullBatch, b: HullBatch):
    """Best face axis of a against b: separation (k,) [m] and face (k,)."""
    sep = np.matmul(a.normal, b.vertex.transpose(0, 2, 1)).min(axis=2) - a.offset
    f = np.argmax(sep, axis=1)
    return sep[np.arange(len(f)), f], f


def _edge_query(a: HullBatch, b: HullBatch):
    """Best edge-pair axis over the pairs whose Gauss-map arcs cross: separation (k,) [m]
    (-inf without any), edges of a and b (k,) and the axis (k, 3), from a towards b."""
    a1, a2 = (np.take_along_axis(a.normal, a.edge_face[..., s:s + 1], 1) for s in (0, 1))
    b1, b2 = (np.take_along_axis(b.normal, b.edge_face[..., s:s + 1], 1) for s in (0, 1))
    u, w = cross(a1, a2), cross(b1, b2)
    bu1, bu2 = np.matmul(u, b1.transpose(0, 2, 1)), np.matmul(u, b2.transpose(0, 2, 1))
    aw1, aw2 = np.matmul(a1, w.transpose(0, 2, 1)), np.matmul(a2, w.transpose(0, 2, 1))
    arcs = (bu1 * bu2 < 0.0) & (aw1 * aw2 < 0.0)  # each arc crosses the other's great circle
    arcs &= bu1 * aw2 < 0.0  # ... on the same side of the sphere
    p, i, j = np.nonzero(arcs)
    pa, da = _edge_points(a, p, i)
    pb, db = _edge_points(b, p, j)
    axis = cross(da, db)
    length = np.linalg.norm(axis, axis=1)
    ok = length > PARALLEL_REL * np.linalg.norm(da, axis=1) * np.linalg.norm(db, axis=1)
    axis /= np.maximum(length, 1e-300)[:, None]
    axis *= np.where(np.einsum("ki,ki->k", axis, pa - a.centre[p]) < 0.0, -1.0, 1.0)[:, None]
    sep = np.where(ok, np.einsum("ki,ki->k", axis, pb - pa), -np.inf)
    k, none = len(a.centre), np.zeros(len(a.centre), np.int64)  # a -inf candidate per row
    p, i, j = np.r_[p, np.arange(k)], np.r_[i, none], np.r_[j, none]
    sep, axis = np.r_[sep, np.full(k, -np.inf)], np.concatenate([axis, np.zeros((k, 3))])
    order = np.lexsort((-sep, p))
    first = order[np.diff(p[order], prepend=-1) != 0]
    return sep[first], i[first], j[first], axis[first]


def _edge_points(h: HullBatch, row: np.ndarray, e: np.ndarray):
    """Start (n, 3) and start-to-end vector (n, 3) of edges e of rows ``row`` [m]."""
    ends = h.vertex[row[:, None], h.edge[row, e]]
    return ends[:, 0], ends[:, 1] - ends[:, 0]


def _area(h: HullBatch, face: np.ndarray) -> np.ndarray:
    """Twice the areas (k,) [m^2] of faces ``face`` (k,) (loops are padded with their first
    corner, which adds nothing to the fan from it)."""
    d = h.polygon(face)[0] - h.polygon(face)[0][:, :1]
    return np.linalg.norm(cross(d[:, :-1], d[:, 1:]).sum(axis=1), axis=1)


def _face_contacts(ref: HullBatch, face: np.ndarray, inc: HullBatch, margin, scale):
    """Clip each row's incident face against reference face ``face``: (pair, point, normal,
    sep, feature), normals outward from ``ref``.

    The incident hull's deepest corner joins the candidates when the clip lost it (it lies
    beyond the reference face's edges and is deeper than every clipped point by more than the
    axis tolerance, or no clipped point is within the margin): the reported separation then
    stays within that tolerance of the axis's, so speculative points never come late."""
    r = np.arange(len(face))
    n, d = ref.normal[r, face], ref.offset[r, face]
    g = np.argmin(np.einsum("kfi,ki->kf", inc.normal, n), axis=1)
    poly, count, label = _clip(*inc.polygon(g), *ref.side_planes(face))
    height = np.einsum("kvi,ki->kv", inc.vertex, n)
    corner = np.argmin(height, axis=1)
    sep = np.einsum("kmi,ki->km", poly, n) - d[:, None]
    clipped = np.arange(poly.shape[1]) < count[:, None]
    deepest = height[r, corner] - d
    lost = ((np.where(clipped, sep, np.inf).min(axis=1) > deepest + AXIS_TOL_REL * scale)
            | ~(clipped & (sep < margin[:, None])).any(axis=1))
    poly = np.concatenate([poly, inc.vertex[r, corner][:, None]], axis=1)
    sep = np.concatenate([sep, deepest[:, None]], axis=1)
    label = np.concatenate([label, 3000 + corner[:, None]], axis=1)
    ok = np.concatenate([clipped, lost[:, None]], axis=1) & (sep < margin[:, None])
    slot, kept = _spread(poly, sep, ok, n, SPREAD_REL * scale)
    code = _distinct((_code(face, g)[:, None] + label[r[:, None], slot]) % FEATURES, kept)
    pair, s = np.nonzero(kept)
    at = pair, slot[pair, s]
    return pair, poly[at] - 0.5 * sep[at][:, None] * n[pair], n[pair], sep[at], code[pair, s]


def _distinct(code: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """Feature codes (k, s) made distinct within each row's kept slots: a code that wrapped
    onto an earlier one moves on by one (codes of faces with up to 10 corners never wrap)."""
    for s in range(1, code.shape[1]):
        for _ in range(s):
            clash = kept[:, s] & (kept[:, :s] & (code[:, :s] == code[:, s:s + 1])).any(axis=1)
            code[clash, s] = (code[clash, s] + 1) % FEATURES
    return code


def _clip(poly, count, side, side_offset, side_count):
    """Sutherland-Hodgman: polygons (k, m, 3) of ``count`` (k,) corners clipped to the planes
    side . x <= side_offset ((k, q, 3), (k, q); the first ``side_count`` (k,) of each row).

    Returns the clipped polygons (k, m + q, 3), their counts (k,) and a code per corner
    (k, m + q): corner i of the input -> i; where polygon edge E crosses plane j ->
    P + E Q + j, with edge codes i (input edge i) or P + j' (a piece lying on plane j'),
    P and Q being the row's counts (distinct codes, stable while the same features touch)."""
    k, m = poly.shape[:2]
    p_, q_ = count[:, None], side_count[:, None]
    label = np.broadcast_to(np.arange(m), (k, m))
    edge = label
    for j in range(side.shape[1]):
        i = np.arange(m)[None, :]
        nxt = np.where(i + 1 < count[:, None], i + 1, 0)
        dist = np.einsum("kmi,ki->km", poly, side[:, j]) - side_offset[:, j, None]
        inside = (dist <= 0.0) | (j >= q_)
        dist_n, inside_n = (np.take_along_axis(a, nxt, 1) for a in (dist, inside))
        cross = (i < count[:, None]) & (inside != inside_n)
        t = np.where(cross, dist / np.where(cross, dist - dist_n, 1.0), 0.0)
        x = poly + t[..., None] * (np.take_along_axis(poly, nxt[..., None], 1) - poly)
        ok = np.stack([(i < count[:, None]) & inside, cross], axis=2).reshape(k, 2 * m)
        pts = np.stack([poly, x], axis=2).reshape(k, 2 * m, 3)
        lab = np.stack([label, p_ + edge * q_ + j], axis=2).reshape(k, 2 * m)
        edg = np.stack([edge, np.where(inside, p_ + j, edge)], axis=2).reshape(k, 2 * m)
        order = np.argsort(~ok, axis=1, kind="stable")[:, :m + 1]
        poly = np.take_along_axis(pts, order[..., None], 1)
        label, edge = (np.take_along_axis(a, order, 1) for a in (lab, edg))
        count = np.minimum(ok.sum(axis=1), m + 1)  # more: rounding on a sliver
        m += 1
    return poly, count, label


def _spread(p, sep, ok, n, eps):
    """Of the points p (k, m, 3) marked ``ok`` keep at most 4 per row: the deepest, the
    farthest from it and the two spanning the largest areas either side of their line (points
    closer than ``eps`` (k,) [m] count as one; near-ties go to the first slot, so rounding does
    not make the choice jump). Returns slots (k, 4) into m and whether each is kept (k, 4)."""
    r = np.arange(len(p))
    i0 = _first(-sep, ok, eps[:, None])
    d = p - p[r, i0][:, None]
    far = np.einsum("kmi,kmi->km", d, d)
    i1 = _first(far, ok, 1e-9 * far.max(axis=1, keepdims=True))
    length = np.sqrt(far[r, i1])
    area = np.einsum("kmi,ki->km", cross(d[r, i1][:, None], d), n)
    i2, i3 = (_first(a, ok, 1e-9 * np.abs(area).max(axis=1, keepdims=True)) for a in (area, -area))
    has1 = ok.any(axis=1) & (length > eps)
    kept = np.stack([ok.any(axis=1), has1, has1 & (area[r, i2] > eps * length),
                     has1 & (area[r, i3] < -eps * length)], axis=1)
    return np.stack([i0, i1, i2, i3], axis=1), kept


def _first(value, ok, tie):
    """Per row the first slot marked ``ok`` whose value is within ``tie`` of the largest."""
    best = np.max(np.where(ok, value, -np.inf), axis=1, keepdims=True)
    return np.argmax(ok & (value >= best - tie), axis=1)


def _edge_contacts(a: HullBatch, b: HullBatch, ea, eb, axis, sep):
    """One point midway between the closest points of edges ea of a and eb of b."""
    r = np.arange(len(ea))
    pa, da = _edge_points(a, r, ea)
    pb, db = _edge_points(b, r, eb)
    s, t = _closest_on_segments(pa, da, pb, db)
    point = 0.5 * (pa + s[:, None] * da + pb + t[:, None] * db)
    return point, axis, sep, _code(np.minimum(ea, eb) + 5000, np.maximum(ea, eb))


def _closest_on_segments(p, u, q, v):
    """Parameters s, t in [0, 1] of the closest points p + s u, q + t v of segments
    (..., 3) [m] (zero lengths allowed)."""
    lu, lv = np.linalg.norm(u, axis=-1), np.linalg.norm(v, axis=-1)
    du, dv = (x / np.maximum(n, 1e-300)[..., None] for x, n in ((u, lu), (v, lv)))
    s, t = closest_segments(p + 0.5 * u, du, 0.5 * lu, q + 0.5 * v, dv, 0.5 * lv)
    return 0.5 + s / np.maximum(lu, 1e-300), 0.5 + t / np.maximum(lv, 1e-300)


# --- capsule core outside the hull (in the hull's frame) ---------------------------------------

def _segment_apart(h: HullBatch, p0, u, radius, margin, rows):
    """Contacts of hulls h with capsules whose cores p0 + t u, t in [0, 1] ((k, 3) [m]) lie
    outside them: one point at the closest points, or two (the core clipped to the face's
    prism) when the closest direction is a face normal (pair (as ``rows``), point, normal,
    sep, feature)."""
    r = np.arange(len(p0))
    scale = h.radius + 0.5 * np.linalg.norm(u, axis=1) + radius
    e0 = np.take_along_axis(h.vertex, h.edge[..., :1], axis=1)
    de = np.take_along_axis(h.vertex, h.edge[..., 1:], axis=1) - e0
    dist, q, q_core, code = _segment_closest(h, e0, de, p0, u)
    normal = (q_core - q) / np.maximum(dist, 1e-300)[:, None]
    sep = dist - radius
    align = np.einsum("kfi,ki->kf", h.normal, normal)
    face = np.argmax(align, axis=1)
    t, ends, clipped = h.clip_segment(face, p0, u)
    pts = p0[:, None] + t[..., None] * u[:, None]
    n, d = h.normal[r, face], h.offset[r, face]
    sep2 = np.einsum("kji,ki->kj", pts, n) - d[:, None] - radius[:, None]
    keep2 = ((align[r, face] >= FACE_ALIGN) & clipped)[:, None] & (sep2 < margin[:, None])
    keep2[:, 1] &= (t[:, 1] - t[:, 0]) * np.linalg.norm(u, axis=1) > SPREAD_REL * scale
    # ... unless the clip lost the closest point (beyond the face's edges)
    keep2 &= (np.where(keep2, sep2, np.inf).min(axis=1) <= sep + AXIS_TOL_REL * scale)[:, None]
    one = np.nonzero(~keep2.any(axis=1) & (sep < margin))[0]
    two, _ = np.nonzero(keep2)
    sep_all = np.concatenate([sep2[keep2], sep[one]])
    normal_all = np.concatenate([n[two], normal[one]])
    hull_side = np.concatenate([pts[keep2] - (sep2[keep2] + radius[two])[:, None] * n[two],
                                q[one]])
    return (rows[np.concatenate([two, one])], hull_side + 0.5 * sep_all[:, None] * normal_all,
            normal_all, sep_all,
            np.concatenate([(_code(face[two]) + ends[keep2]) % FEATURES, code[one]]))


def _segment_closest(h: HullBatch, e0, de, p0, u):
    """Closest points of hull and core (exact while apart) from the ends' closest hull points
    and the closest points to every hull edge e0 + s de ((k, e, 3) [m]): distance (k,) [m],
    hull point (k, 3), core point (k, 3), feature (k,)."""
    r = np.arange(len(p0))
    ends = [h.closest(p) for p in (p0, p0 + u)]
    s, t = _closest_on_segments(e0, de, p0[:, None], u[:, None])
    qa, qb = e0 + s[..., None] * de, p0[:, None] + t[..., None] * u[:, None]
    e = np.argmin(np.einsum("kei,kei->ke", qb - qa, qb - qa), axis=1)
    qa, qb, s, t = qa[r, e], qb[r, e], s[r, e], t[r, e]
    dist = np.stack([ends[0][0], ends[1][0], np.linalg.norm(qb - qa, axis=1)], axis=1)
    which = np.argmin(dist, axis=1)
    end = [np.where(x <= 0.0, 0, np.where(x >= 1.0, 1, 2)) for x in (s, t)]
    code = np.stack([_code(*ends[0][3:], 0), _code(*ends[1][3:], 1), _code(4, e, *end)], 1)
    return (dist[r, which], np.stack([ends[0][1], ends[1][1], qa], axis=1)[r, which],
            np.stack([p0, p0 + u, qb], axis=1)[r, which], code[r, which])
