"""Contacts with triangle meshes: Mesh colliders (a bowl, terrain, Suzanne: open or closed) and
concave Mesh bodies (a ring, a torus knot: closed meshes that move).

Three kinds of points meet in each pair with a mesh, through the mesh's hierarchy (built once
in the mesh's own frame: a rigid mesh never needs a refit) or, for a convex partner, its exact
signed distance:

* a convex body's contact points — a box's or hull's corners, a sphere's centre, a capsule's
  axis ends, with their radius — against the mesh's closest surface points;
* a mesh's vertices against its partner: a convex shape's signed distance (sphere, box,
  capsule, hull planes), another mesh's closest surface points (a Mesh body's against a Mesh
  body or collider, a Mesh collider's against a Mesh body);
* a mesh's edges against a convex partner: the point along an edge deepest in the shape,
  where that lies between the edge's ends (a ridge under a box's face, a box's edge across a
  mesh edge, a capsule lying across a crest: no vertex of either is there).

A point closer than its pair's margin becomes a contact along the partner's surface normal at
the closest point. An open Mesh collider has no inside: its surface faces the side the other
body's centre of mass is on, whatever the winding; a Mesh body, and a watertight Mesh collider
wound outward, is closed and its outside is outside (a ring around a peg has its centre of mass
inside the peg). Each pair keeps up to 3 places it touches at, each with at most 4 points (the
widest support with the deepest point). Between two meshes only vertices are seen: two of
their edges crossing between their ends are not (dense meshes leave small gaps).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import cross
from ..collision.build import build_bvh
from ..collision.distance import closest_points
from ..collision.mesh import TriangleMesh
from .collide import (BOX_CORNERS, FEATURES, HALF_SPACE, SPECULATIVE, SUPPORT_TOLERANCE, Found,
                      approach, reduce_manifolds)
from .mesh_parts import MeshEdges, VertexCells
from .model import BOX, CAPSULE, HULL, MESH, SPHERE


SITES = 3  # places a pair with a mesh keeps apart, each with up to 4 points (:func:`_sites`)
SITE_FRACTION = 0.5  # a site's reach: this fraction of the smaller body's bound radius
EDGE_STEPS = 12  # cutting-plane steps for an edge's deepest point (:func:`_deepest_along`)
EDGE_TOLERANCE = 1e-6  # [m] how close its distance is to the least one when it stops
EDGE_END = 1e-3  # an edge's deepest point this near its ends is its end's (vertex) contact


@dataclass(frozen=True)
class MeshShape:
    """A mesh in its body's frame (from the body's x, unscaled): hierarchy, bounds (lo, hi
    (3,), grown by the thickness), vertices (v, 3), whether it is closed (its outside is
    outside: a Mesh body, a watertight Mesh collider), whether it is a rigid body's (a
    collider's size says nothing about where it touches), its edges and its vertices by cells
    (:mod:`.mesh_parts`)."""

    bvh: object
    lo: np.ndarray
    hi: np.ndarray
    vertices: np.ndarray
    closed: bool
    body: bool = False
    edges: MeshEdges | None = None
    cells: VertexCells | None = None

    @property
    def radius(self) -> float:
        """[m] a sphere about the frame's origin holding the mesh (and its thickness)."""
        return float(np.linalg.norm(np.maximum(np.abs(self.lo), np.abs(self.hi))))


class MeshCache:
    """Hierarchies of the meshes of a solver (Mesh colliders, Mesh bodies), kept between frames
    while a mesh's (scaled, local) vertices stay the same. One per solver."""

    def __init__(self):
        self._known: dict[str, tuple] = {}

    def _entry(self, name: str, vertices: np.ndarray, triangles: np.ndarray):
        """(vertices, triangles, hierarchy, closed, edges, cells) of the mesh, built again when
        its vertices or triangles are not those of last time (compared by value: a frame's
        inputs are new arrays)."""
        known = self._known.get(name)
        if known is None or not (_same(known[0], vertices) and _same(known[1], triangles)):
            mesh = TriangleMesh(vertices, triangles, name=name)
            known = (vertices, triangles, build_bvh(mesh, "aabb"),
                     watertight(vertices, triangles), MeshEdges.of(vertices, triangles),
                     VertexCells(vertices))
            self._known[name] = known
        return known

    def bvh(self, name: str, vertices: np.ndarray, triangles: np.ndarray):
        return self._entry(name, vertices, triangles)[2]

    def shape(self, name: str, vertices, triangles, thickness: float = 0.0,
              body: bool = False) -> MeshShape:
        """A mesh's :class:`MeshShape`; a Mesh collider that is watertight and wound outward
        is closed too (a peg: a ring around it has its centre inside it)."""
        verts = np.asarray(vertices, dtype=np.float64)
        verts, _, bvh, tight, edges, cells = self._entry(name, verts,
                                                         np.asarray(triangles, np.int64))
        lo, hi = cells.bounds()
        return MeshShape(bvh, lo - thickness, hi + thickness, verts, body or tight, body, edges,
                         cells)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a is b or (a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a, b))


def watertight(vertices: np.ndarray, triangles: np.ndarray) -> bool:
    """Every edge is used once in each direction (a closed, consistently wound surface) and the
    enclosed volume is positive (wound outward)."""
    t = np.asarray(triangles, np.int64)
    if not len(t):
        return False
    n = len(vertices)
    directed = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    code = directed[:, 0] * n + directed[:, 1]
    reverse = directed[:, 1] * n + directed[:, 0]
    if len(np.unique(code)) != len(code) or not np.isin(reverse, code).all():
        return False
    a, b, c = (np.asarray(vertices, np.float64)[t[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, cross(b, c)).sum()) > 0.0


def _points(bodies, rot: np.ndarray, idx: np.ndarray):
    """(owner, feature, world point, radius) of the contact points of convex bodies ``idx``."""
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


def _side(mesh: MeshShape, bodies, rot, g: int, rows: np.ndarray) -> np.ndarray:
    """(len(rows),) +1 or -1: the side of mesh ``g`` the centres of mass of bodies ``rows`` are
    on (an open mesh has no inside: a body meets it from where it is, whatever the faces'
    winding); +1 for a closed Mesh body."""
    if mesh.closed or not len(rows):
        return np.ones(len(rows))
    local = np.einsum("ji,nj->ni", rot[g], bodies.x[rows] - bodies.x[g])
    return np.where(closest_points(mesh.bvh, local).signed_distance < 0.0, -1.0, 1.0)


def _near(bodies, rot, reach, g: int, mesh: MeshShape) -> np.ndarray:
    """Bodies whose bounds reach into mesh ``g``'s box this search, one of the pair dynamic."""
    rows = np.nonzero((bodies.shape != HALF_SPACE) & (bodies.dynamic | bodies.dynamic[g]))[0]
    rows = rows[rows != g]
    local = np.einsum("ji,nj->ni", rot[g], bodies.x[rows] - bodies.x[g])  # R^T (x - x_g)
    grow = (bodies.bound[rows] + reach[rows] + reach[g] + SPECULATIVE)[:, None]
    inside = ((local + grow >= mesh.lo) & (local - grow <= mesh.hi)).all(axis=1)
    return rows[inside & bodies.searched(rows, g)]


@dataclass(frozen=True)
class _Points:
    """Points of bodies ``owner`` against the surface of bodies ``other`` (k each): world
    points on the owner, the other's outward surface normal there (k, 3), the separation."""

    owner: np.ndarray
    other: np.ndarray
    feature: np.ndarray
    p: np.ndarray
    normal: np.ndarray
    separation: np.ndarray


def _on_mesh(bodies, rot, g: int, mesh: MeshShape, owner, feature, p, radius, margin):
    """Points p (k, 3) of ``owner`` (radius each) against mesh g's surface."""
    lp = np.einsum("ji,nj->ni", rot[g], p - bodies.x[g])
    cp = closest_points(mesh.bvh, lp, max_distance=float((margin + radius).max()))
    owners, which = np.unique(owner, return_inverse=True)
    side = _side(mesh, bodies, rot, g, owners)[which]
    found = cp.triangle >= 0
    sep = np.where(found, side * cp.signed_distance - radius - bodies.radius[g], np.inf)
    keep = sep < margin
    n_out = np.einsum("ij,nj->ni", rot[g], cp.normal[keep]) * side[keep, None]
    return _Points(owner[keep], np.full(int(keep.sum()), g), feature[keep], p[keep], n_out,
                   sep[keep])


def _convex_on_mesh(bodies, rot, reach, g: int, mesh: MeshShape, near) -> _Points:
    """The contact points of the convex bodies ``near`` against mesh g."""
    convex = near[bodies.shape[near] != MESH]
    if not len(convex):
        return None
    owner, feature, p, radius = _points(bodies, rot, convex)
    return _on_mesh(bodies, rot, g, mesh, owner, feature, p, radius,
                    SPECULATIVE + reach[owner] + reach[g])


def _world(bodies, rot, g: int, mesh: MeshShape, rows=slice(None)) -> np.ndarray:
    """World positions of mesh g's vertices ``rows``."""
    return bodies.x[g] + mesh.vertices[rows] @ rot[g].T


def _close_vertices(bodies, rot, g: int, mesh: MeshShape, rows, radii):
    """(k, v) pairs: mesh g's vertices v within radii[k] of the centres of bodies rows[k],
    read from the mesh's cells (in its own frame: the others are not looked at)."""
    local = (bodies.x[rows] - bodies.x[g]) @ rot[g]  # R^T (x - x_g)
    return mesh.cells.near(local, radii)


def _vertices_on(bodies, rot, reach, g: int, mesh: MeshShape, near) -> list[_Points]:
    """Mesh g's vertices against the bodies ``near``: meshes (g a Mesh body or collider) by
    their hierarchy, convex shapes by their signed distance."""
    out = []
    meshes = near[bodies.shape[near] == MESH]
    world = _world(bodies, rot, g, mesh) if len(meshes) else None
    for o in meshes:
        other = bodies.meshes[int(o)]
        margin = SPECULATIVE + reach[g] + reach[o]
        local = (world - bodies.x[o]) @ rot[o]
        sel = np.nonzero(((local + margin >= other.lo) & (local - margin <= other.hi))
                         .all(axis=1))[0]
        if len(sel):
            out.append(_on_mesh(bodies, rot, int(o), other, np.full(len(sel), g), sel,
                                world[sel], np.zeros(len(sel)), margin))
    convex = near[bodies.shape[near] != MESH]
    if len(convex):
        margin = SPECULATIVE + reach[g] + reach[convex]
        o, v = _close_vertices(bodies, rot, g, mesh, convex, bodies.bound[convex] + margin)
        at = _world(bodies, rot, g, mesh, v)
        sd, n_out = convex_distance(bodies, rot, convex[o], at)
        sd -= bodies.radius[g]  # a Mesh collider's thickness
        keep = sd < margin[o]
        out.append(_Points(np.full(int(keep.sum()), g), convex[o][keep], v[keep],
                           at[keep], n_out[keep], sd[keep]))
    return out


def _edges_on(bodies, rot, reach, g: int, mesh: MeshShape, near) -> _Points | None:
    """Mesh g's edges against the convex bodies ``near``:
    where an edge passes into a shape between its ends — a ridge under a box's face, a box's
    edge across a mesh edge, a capsule lying across a crest — the point along it deepest in
    the shape, which neither the shape's corners nor the mesh's vertices reach
    (:func:`_deepest_along`)."""
    convex = near[bodies.shape[near] != MESH]
    edges = mesh.edges
    if not len(convex) or edges is None or not len(edges.pairs):
        return None
    margin = SPECULATIVE + reach[g] + reach[convex]
    ball = bodies.bound[convex] + margin
    # an edge passing within ``ball`` of a centre has an end within ball + its length
    o, v = _close_vertices(bodies, rot, g, mesh, convex, ball + edges.longest)
    which, e = edges.touching(v)
    count = len(edges.pairs)
    key = np.unique(o[which] * count + e)
    o, e = key // count, key % count
    ends = _world(bodies, rot, g, mesh, edges.pairs[e].ravel()).reshape(-1, 2, 3)
    p0 = ends[:, 0]
    d = ends[:, 1] - p0
    c = bodies.x[convex[o]]
    t = np.clip(np.einsum("ki,ki->k", c - p0, d) /
                np.maximum(np.einsum("ki,ki->k", d, d), 1e-300), 0.0, 1.0)
    close = np.linalg.norm(p0 + t[:, None] * d - c, axis=1) <= ball[o]
    o, e, p0, d = o[close], e[close], p0[close], d[close]
    limit = margin[o] + bodies.radius[g]  # (a Mesh collider's thickness)
    t, sd, n_out = _deepest_along(bodies, rot, convex[o], p0, d, limit)
    keep = (sd < limit) & (t > EDGE_END) & (t < 1.0 - EDGE_END)
    return _Points(np.full(int(keep.sum()), g), convex[o][keep], len(mesh.vertices) + e[keep],
                   p0[keep] + t[keep, None] * d[keep], n_out[keep],
                   sd[keep] - bodies.radius[g])


def _deepest_along(bodies, rot, rows: np.ndarray, p0: np.ndarray, d: np.ndarray,
                   limit: np.ndarray):
    """(t, signed distance, the shape's outward normal there) at the point p0 + t d, t in
    [0, 1], where each segment goes deepest into the convex shape of body ``rows``; a
    distance of +inf where that is at an end (the end's own test covers it), and one not under
    ``limit`` (k,) where it surely is not. A convex shape's signed distance is convex along a line, and its slope
    there is the shape's normal along d: from the ends' values and slopes the two tangent
    lines meet at a lower bound of the least value; the distance there (Kelley's cutting
    planes) replaces the end whose side the slope says the least value is not on, until the
    value found is within EDGE_TOLERANCE of the bound — one step for a box, whose distance
    is piecewise linear, a few for round shapes."""
    k = len(rows)
    f, n = convex_distance(bodies, rot, np.concatenate([rows, rows]), np.concatenate([p0, p0 + d]))
    fa, fb = f[:k].copy(), f[k:].copy()
    sa, sb = np.einsum("ki,ki->k", n[:k], d), np.einsum("ki,ki->k", n[k:], d)
    a, b = np.zeros(k), np.ones(k)
    best_t, best_f, best_n = np.zeros(k), np.full(k, np.inf), np.zeros((k, 3))
    live = np.nonzero((sa < 0.0) & (sb > 0.0))[0]  # falling at the start, rising at the end
    for _ in range(EDGE_STEPS):
        if not len(live):
            break
        ta, tb = a[live], b[live]
        t = (fb[live] - fa[live] + sa[live] * ta - sb[live] * tb) / (sa[live] - sb[live])
        low = fa[live] + sa[live] * (t - ta)
        t = np.clip(t, ta + 1e-9, tb - 1e-9)
        ft, nt = convex_distance(bodies, rot, rows[live], p0[live] + t[:, None] * d[live])
        st = np.einsum("ki,ki->k", nt, d[live])
        better = ft < best_f[live]
        hit = live[better]
        best_t[hit], best_f[hit], best_n[hit] = t[better], ft[better], nt[better]
        left = st < 0.0  # still falling: the least value lies beyond t
        on = live[left]
        a[on], fa[on], sa[on] = t[left], ft[left], st[left]
        on = live[~left]
        b[on], fb[on], sb[on] = t[~left], ft[~left], st[~left]
        live = live[(ft - low > EDGE_TOLERANCE) & (low < limit[live])]
    found = np.nonzero(best_f < limit)[0]
    if len(found):
        best_n[found] = _normal_across(bodies, rot, rows[found], p0[found], d[found],
                                       best_t[found], best_n[found])
    return best_t, best_f, best_n


def _normal_across(bodies, rot, rows, p0, d, t, n):
    """The contact normal where a segment goes deepest into a shape, at t: where two faces
    meet there (the segment crossing a box's edge, a kink of the distance along it) the
    shape's normal jumps from one face's to the other's, and the normal that pushes the
    segment out is the blend of the two square to it (for two crossing edges, their common
    perpendicular); elsewhere the shape's normal ``n`` there."""
    k = len(rows)
    step = EDGE_TOLERANCE / np.maximum(np.linalg.norm(d, axis=1), 1e-300)
    ta, tb = np.maximum(t - step, 0.0), np.minimum(t + step, 1.0)
    _, side = convex_distance(bodies, rot, np.concatenate([rows, rows]),
                              np.concatenate([p0 + ta[:, None] * d, p0 + tb[:, None] * d]))
    na, nb = side[:k], side[k:]
    sa, sb = np.einsum("ki,ki->k", na, d), np.einsum("ki,ki->k", nb, d)
    kink = (sa < 0.0) & (sb > 0.0)
    blend = (sb[:, None] * na - sa[:, None] * nb) / np.where(kink, sb - sa, 1.0)[:, None]
    size = np.linalg.norm(blend, axis=1)
    use = kink & (size > 1e-9)
    return np.where(use[:, None], blend / np.where(use, size, 1.0)[:, None], n)


def convex_distance(bodies, rot, rows: np.ndarray, p: np.ndarray):
    """Signed distance [m] (k,) of world points p (k, 3) to the convex shapes of bodies
    ``rows`` (k,) (sphere, box, capsule, hull), and the shapes' outward unit normals (k, 3)
    at their closest surface points (for a hull: of the face it is least inside)."""
    local = np.einsum("kji,kj->ki", rot[rows], p - bodies.centres(rot)[rows])
    sd, n = np.full(len(rows), np.inf), np.zeros((len(rows), 3))
    shape = bodies.shape[rows]
    sel = np.nonzero(shape == SPHERE)[0]
    _unit_into(local[sel], sd, n, sel, -bodies.radius[rows[sel]])
    sel = np.nonzero(shape == CAPSULE)[0]
    if len(sel):
        half = bodies.half[rows[sel], 2]
        axis = local[sel].copy()
        axis[:, 2] -= np.clip(axis[:, 2], -half, half)
        _unit_into(axis, sd, n, sel, -bodies.radius[rows[sel]])
    sel = np.nonzero(shape == BOX)[0]
    if len(sel):
        q = np.abs(local[sel]) - bodies.half[rows[sel]]
        out = np.maximum(q, 0.0)
        outside = np.linalg.norm(out, axis=1)
        face = np.argmax(q, axis=1)
        inward = np.zeros_like(q)
        inward[np.arange(len(sel)), face] = 1.0
        dirs = np.where((outside > 0.0)[:, None], out / np.maximum(outside, 1e-300)[:, None],
                        inward) * np.where(local[sel] < 0.0, -1.0, 1.0)
        sd[sel] = outside + np.minimum(q.max(axis=1), 0.0)
        n[sel] = dirs
    sel = np.nonzero(shape == HULL)[0]
    if len(sel):
        batch = bodies.hulls.batch(bodies.hull_index[rows[sel]])
        lp = np.einsum("kji,kj->ki", rot[rows[sel]], p[sel] - bodies.x[rows[sel]])
        planes = np.einsum("kfi,ki->kf", batch.normal, lp) - batch.offset
        face = np.argmax(planes, axis=1)
        sd[sel] = planes[np.arange(len(sel)), face]
        # the hull's normals are in the body's axes, as the other shapes' local ones
        n[sel] = batch.normal[np.arange(len(sel)), face]
    return sd, np.einsum("kij,kj->ki", rot[rows], n)


def _unit_into(d: np.ndarray, sd, n, sel, add) -> None:
    """sd[sel] = |d| + add, n[sel] = d / |d| (any unit vector at 0)."""
    length = np.linalg.norm(d, axis=1)
    sd[sel] = length + add
    n[sel] = np.where((length > 1e-12)[:, None], d / np.maximum(length, 1e-300)[:, None],
                      [0.0, 0.0, 1.0])


def mesh_contacts(bodies, rot: np.ndarray, reach: np.ndarray, interval: float) -> Found:
    """Contacts of every pair with a mesh (Mesh colliders and Mesh bodies) and a dynamic side,
    at most 4 per pair (ranked by the least separation expected within ``interval`` [s])."""
    parts, edges = [], []
    for g, mesh in bodies.meshes.items():
        near = _near(bodies, rot, reach, g, mesh)
        if len(near):
            parts.append(_convex_on_mesh(bodies, rot, reach, g, mesh, near))
            parts += _vertices_on(bodies, rot, reach, g, mesh, near)
            edges.append(_edges_on(bodies, rot, reach, g, mesh, near))
    parts = [p for p in parts if p is not None and len(p.owner)]
    edges = [p for p in edges if p is not None and len(p.owner)]
    if not parts and not edges:
        return Found.join([])
    owner, other, feature, p, n_out, sep = (np.concatenate([getattr(q, f) for q in parts + edges])
                                            for f in ("owner", "other", "feature", "p",
                                                      "normal", "separation"))
    on_edge = np.arange(len(owner)) >= sum(len(q.owner) for q in parts)
    point = p - 0.5 * sep[:, None] * n_out
    n = len(bodies)
    pair = np.minimum(owner, other) * n + np.maximum(owner, other)
    rank = np.minimum(sep, sep + interval * approach(bodies, owner, other, point, n_out))
    size = bodies.bound.copy()
    size[[g for g, m in bodies.meshes.items() if not m.body]] = np.inf  # colliders: no size
    place = SITE_FRACTION * np.minimum(size[owner], size[other])
    if on_edge.any():  # an edge's point where a vertex or corner already holds the place: left out
        new = ~_covered(pair, point, rank, on_edge, place)
        owner, other, feature, point, n_out, sep, pair, rank, place = (
            a[new] for a in (owner, other, feature, point, n_out, sep, pair, rank, place))
    site = _sites(pair, point, rank, place)
    sel = reduce_manifolds(pair * SITES + site, point, rank)
    owner, other, n_out = owner[sel], other[sel], n_out[sel]
    # one manifold per pair, every point from its lower row a to its higher row b (both
    # directions meet in a pair of meshes): the normal from a to b
    flip = owner > other
    key = (pair[sel] * 2 + flip) * FEATURES + feature[sel] % FEATURES
    return Found(np.where(flip, other, owner), np.where(flip, owner, other), point[sel],
                 np.where(flip[:, None], n_out, -n_out), sep[sel], key)


def _covered(pair, point, rank, on_edge, reach) -> np.ndarray:
    """(k,) the edge points (``on_edge``) that a vertex or corner point of the same pair
    within ``reach`` [m] of it, and at most SUPPORT_TOLERANCE less deep (by ``rank``),
    already holds: an edge adds what the vertices miss (a crest under a face), not more points
    where they touch already (a box in a bowl, whose corners meet the bowl beside the edges
    under its rim)."""
    out = np.zeros(len(pair), bool)
    e, v = np.nonzero(on_edge)[0], np.nonzero(~on_edge)[0]
    if not len(e) or not len(v):
        return out
    order = v[np.argsort(pair[v], kind="stable")]
    keys = pair[order]
    lo = np.searchsorted(keys, pair[e], "left")
    count = np.searchsorted(keys, pair[e], "right") - lo
    which = np.repeat(np.arange(len(e)), count)
    near = order[np.repeat(lo, count) + np.arange(int(count.sum())) -
                 np.repeat(np.cumsum(count) - count, count)]
    mine = e[which]
    held = (np.linalg.norm(point[near] - point[mine], axis=1) <= reach[mine]) & \
        (rank[near] <= rank[mine] + SUPPORT_TOLERANCE)
    out[np.unique(mine[held])] = True
    return out


def _sites(pair: np.ndarray, point: np.ndarray, rank: np.ndarray, reach: np.ndarray):
    """(k,) each point's site in its pair, 0 .. SITES - 1: the points within ``reach`` (k,) [m]
    of the pair's deepest point (by ``rank``), then of the deepest of the rest, and so on; the
    last site takes what is left. A concave pair touches at several places (a ring resting
    across two others, a ring on a peg's side and on the ground): each place keeps its own
    support, where one manifold of the widest points would keep only the deepest place."""
    site = np.full(len(pair), SITES - 1)
    left = np.arange(len(pair))
    for k in range(SITES - 1):
        if not len(left):
            break
        order = left[np.lexsort((rank[left], pair[left]))]
        heads = order[np.r_[True, pair[order][1:] != pair[order][:-1]]]
        deepest = heads[np.searchsorted(pair[heads], pair[left])]
        here = np.linalg.norm(point[left] - point[deepest], axis=1) <= reach[left]
        site[left[here]] = k
        left = left[~here]
    return site
