"""Convex-hull rigid shapes: a mesh's vertices -> polyhedron (planar faces, unique edges) ->
padded arrays that batch many hulls (one row per pair) for the narrow phase.

Quickhull (:func:`~physanim.core.collision.hull.convex_hull`) returns triangles; coplanar ones
(a cube's face is two) are merged into one polygon so that a face is a face: the separating-
axis test then sees each plane once, and a resting box clips one quad, not two triangles.
Triangles join a face when all their corners lie within ``MERGE_REL`` x the hull's size of the
face's first (largest) triangle's plane. Corners left with fewer than three faces around them
(interior or collinear after merging) are dropped, so V - E + F = 2 holds exactly.

Padding for batches repeats real data, which changes no result: a repeated corner changes no
support point, a repeated face or edge no maximum, a loop padded with its first corner adds
only edges of zero length (side planes of zero, true everywhere).
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..transforms import cross
from ..collision.hull import convex_hull
from ..errors import PhysanimError
from ..validate import frozen

MERGE_REL = 1e-6  # coplanarity tolerance for merging hull triangles, relative to the hull size
FLAT_REL = 1e-5  # a hull thinner than this (relative to its size) counts as flat


@dataclass(frozen=True)
class HullShape:
    """A convex polyhedron in its body's local frame.

    Attributes:
        name: the object's name (messages).
        vertex: (h, 3) corners [m].
        face_normal: (f, 3) unit outward normals. face_offset: (f,) [m]: x is inside every
            face when face_normal . x <= face_offset.
        face_loop: (l,) corner indices of every face, counter-clockwise seen from outside,
            face after face; face_loop_start, face_loop_count: (f,) each face's range in it.
        edge: (e, 2) corner indices, edge[:, 0] < edge[:, 1].
        edge_direction: (e, 3) unit vectors from edge[:, 0] to edge[:, 1].
        edge_face: (e, 2) the faces either side; face edge_face[:, 0] walks the edge from
            edge[:, 0] to edge[:, 1].
        centre: (3,) mean of the corners [m]. radius: farthest corner from ``centre`` [m].
    """

    name: str
    vertex: np.ndarray
    face_normal: np.ndarray
    face_offset: np.ndarray
    face_loop: np.ndarray
    face_loop_start: np.ndarray
    face_loop_count: np.ndarray
    edge: np.ndarray
    edge_direction: np.ndarray
    edge_face: np.ndarray
    centre: np.ndarray
    radius: float

    @classmethod
    def from_points(cls, points, name: str = "hull") -> HullShape:
        """The convex hull of (n, 3) points [m] (a mesh's vertices, local).

        Raises:
            PhysanimError: naming ``name`` when the points do not enclose a volume.
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if len(p) < 4:
            _flat(name, f"has {len(p)} vertices")
        hull = convex_hull(p)
        if hull.dimension < 3:
            _flat(name, f"has its vertices in a {('point', 'line', 'plane')[hull.dimension]}")
        corners = p[hull.vertices]
        size = float(np.ptp(corners, axis=0).max())
        t = p[hull.triangles]
        n = cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        proj = (n / np.linalg.norm(n, axis=1)[:, None]) @ corners.T
        if np.ptp(proj, axis=1).min() < FLAT_REL * size:
            _flat(name, f"is flat (thinner than {FLAT_REL:g} of its size)")
        loops = _merged_loops(p, hull.triangles, MERGE_REL * size)
        used, loop = np.unique(np.concatenate(loops), return_inverse=True)
        vertex = p[used]
        count = np.array([len(lp) for lp in loops], dtype=np.int64)
        start = np.concatenate([[0], np.cumsum(count)[:-1]])
        normal = np.array([_newell(vertex[loop[s:s + c]]) for s, c in zip(start, count)])
        offset = (normal @ corners.T).max(axis=1)  # every corner inside, dropped ones too
        edge, edge_face = _edges(loop, start, count, len(vertex), name)
        d = vertex[edge[:, 1]] - vertex[edge[:, 0]]
        centre = vertex.mean(axis=0)
        return cls(name, frozen(vertex), frozen(normal), frozen(offset),
                   frozen(loop, np.int64), frozen(start, np.int64), frozen(count, np.int64),
                   frozen(edge, np.int64), frozen(d / np.linalg.norm(d, axis=1)[:, None]),
                   frozen(edge_face, np.int64), frozen(centre),
                   float(np.linalg.norm(vertex - centre, axis=1).max()))


def _flat(name: str, what: str):
    raise PhysanimError(f"a convex hull needs a volume, but the mesh {what}; give it a Box "
                        "shape (or a Sphere) instead", obj=name, kind="rigid body")


def _newell(loop: np.ndarray) -> np.ndarray:
    """Unit normal of a (c, 3) polygon, counter-clockwise seen from its front (Newell)."""
    n = cross(loop, np.roll(loop, -1, axis=0)).sum(axis=0)
    return n / np.linalg.norm(n)


def _merged_loops(p: np.ndarray, tris: np.ndarray, tol: float) -> list[np.ndarray]:
    """Corner loops of the faces made by merging coplanar hull triangles (region growing
    from the largest triangle; build time, so plain Python)."""
    t = p[tris]
    n = cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    area = np.linalg.norm(n, axis=1)
    n /= area[:, None]
    owner = {(int(a), int(b)): f for f, tri in enumerate(tris)
             for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0]))}
    group = np.full(len(tris), -1)
    loops = []
    for seed in np.argsort(-area, kind="stable"):
        if group[seed] >= 0:
            continue
        g, stack, plane = len(loops), [int(seed)], float(n[seed] @ t[seed, 0])
        group[seed] = g
        while stack:
            tri = tris[stack.pop()]
            for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
                nb = owner[(int(b), int(a))]
                if group[nb] < 0 and np.abs(t[nb] @ n[seed] - plane).max() <= tol:
                    group[nb] = g
                    stack.append(nb)
        loops.append(_boundary(tris[group == g], owner, group, g))
    return _drop_flat_corners(loops)


def _boundary(tris: np.ndarray, owner: dict, group: np.ndarray, g: int) -> list[int]:
    """The boundary loop of one face's triangles, in their (counter-clockwise) order."""
    nxt = {}
    for tri in tris:
        for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
            if group[owner[(int(b), int(a))]] != g:
                nxt[int(a)] = int(b)
    loop = [min(nxt)]
    while nxt[loop[-1]] != loop[0]:
        loop.append(nxt[loop[-1]])
    return loop


def _drop_flat_corners(loops: list[list[int]]) -> list[np.ndarray]:
    """Loops without corners that fewer than three faces share (collinear after merging)."""
    ids, faces = np.unique(np.concatenate(loops), return_counts=True)
    keep = set(ids[faces >= 3].tolist())
    return [np.array([v for v in lp if v in keep], dtype=np.int64) for lp in loops]


def _edges(loop: np.ndarray, start: np.ndarray, count: np.ndarray, h: int, name: str):
    """Unique edges (e, 2) and the faces either side (e, 2) from the faces' corner loops."""
    face = np.repeat(np.arange(len(count)), count)
    nxt = np.arange(len(loop)) + 1
    nxt[start + count - 1] = start
    a, b = loop, loop[nxt]
    forward = a < b
    key = np.minimum(a, b) * h + np.maximum(a, b)
    order = np.lexsort((~forward, key))
    key, forward, face, a, b = key[order], forward[order], face[order], a[order], b[order]
    if (len(key) % 2 or (key[0::2] != key[1::2]).any() or not forward[0::2].all()
            or forward[1::2].any() or (count < 3).any()):
        raise PhysanimError("its convex hull is degenerate (an edge without two faces); "
                            "give it a Box or Sphere shape", obj=name, kind="rigid body")
    return np.stack([a[0::2], b[0::2]], axis=1), np.stack([face[0::2], face[1::2]], axis=1)


@dataclass(frozen=True)
class HullBatch:
    """One hull per row (k rows, e.g. one per pair), padded to common sizes (V, F, L, E).

    Attributes:
        vertex: (k, V, 3) corners [m] (padding repeats corner 0).
        normal: (k, F, 3) unit face normals; offset: (k, F) [m] (padding repeats face 0).
        loop: (k, F, L) corner indices of each face; loop_count: (k, F).
        edge: (k, E, 2) corner indices; edge_face: (k, E, 2) (padding repeats edge 0).
        centre: (k, 3) [m]; radius: (k,) [m] (see :class:`HullShape`).
    """

    vertex: np.ndarray
    normal: np.ndarray
    offset: np.ndarray
    loop: np.ndarray
    loop_count: np.ndarray
    edge: np.ndarray
    edge_face: np.ndarray
    centre: np.ndarray
    radius: np.ndarray

    def transformed(self, rot: np.ndarray, pos: np.ndarray) -> HullBatch:
        """The same hulls moved by x -> rot x + pos, rot (k, 3, 3), pos (k, 3) [m]."""
        normal = np.einsum("kij,kfj->kfi", rot, self.normal)
        return HullBatch(np.einsum("kij,kvj->kvi", rot, self.vertex) + pos[:, None],
                         normal, self.offset + np.einsum("kfi,ki->kf", normal, pos), self.loop,
                         self.loop_count, self.edge, self.edge_face,
                         np.einsum("kij,kj->ki", rot, self.centre) + pos, self.radius)

    def rows(self, rows: np.ndarray) -> HullBatch:
        """The batch of rows ``rows`` (an index array or mask)."""
        return HullBatch(*(getattr(self, f.name)[rows] for f in fields(self)))

    def polygon(self, face: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Corners (k, L, 3) [m] of face ``face`` (k,) of each row (padded with the first) and
        their counts (k,)."""
        loop = self.loop[np.arange(len(face)), face]
        return (np.take_along_axis(self.vertex, loop[..., None], axis=1),
                self.loop_count[np.arange(len(face)), face])

    def side_planes(self, face: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The planes through the edges of face ``face`` (k,) of each row, at right angles to
        it: outward unit normals (k, L, 3), offsets (k, L) [m] (x is on the face's side when
        normal . x <= offset) and counts (k,) (beyond the count: zero, true for every x)."""
        corner, count = self.polygon(face)  # padded with the first corner: zero sides
        n = self.normal[np.arange(len(face)), face]
        side = cross(np.roll(corner, -1, axis=1) - corner, n[:, None])
        side /= np.maximum(np.linalg.norm(side, axis=2), 1e-300)[..., None]
        return side, np.einsum("kli,kli->kl", side, corner), count

    def closest(self, point: np.ndarray):
        """The hull surface point nearest each row's ``point`` (k, 3) [m].

        Returns:
            distance (k,) [m] signed (< 0 inside: the depth below the nearest face),
            closest (k, 3) surface point [m], normal (k, 3) unit, outward from the hull
            towards the point, and the feature reached: kind (k,) (0 face, 1 edge, 2 corner)
            and its index (k,).
        """
        r = np.arange(len(point))
        height = np.einsum("kfi,ki->kf", self.normal, point) - self.offset
        f = np.argmax(height, axis=1)
        h, n = height[r, f], self.normal[r, f]
        side, side_offset, _ = self.side_planes(f)
        on_face = (h <= 0.0) | (np.einsum("kli,ki->kl", side, point) <= side_offset).all(1)
        e0 = np.take_along_axis(self.vertex, self.edge[..., :1], axis=1)
        d = np.take_along_axis(self.vertex, self.edge[..., 1:], axis=1) - e0
        t = np.clip(np.einsum("kei,kei->ke", point[:, None] - e0, d)
                    / np.einsum("kei,kei->ke", d, d), 0.0, 1.0)
        q = e0 + t[..., None] * d
        dist2 = np.einsum("kei,kei->ke", point[:, None] - q, point[:, None] - q)
        e = np.argmin(dist2, axis=1)
        te, qe = t[r, e], q[r, e]
        dist = np.where(on_face, h, np.sqrt(dist2[r, e]))
        normal = np.where(on_face[:, None], n,
                          (point - qe) / np.maximum(dist, 1e-300)[:, None])
        end = np.where(te == 0.0, 0, np.where(te == 1.0, 1, -1))
        kind = np.where(on_face, 0, np.where(end < 0, 1, 2))
        ident = np.where(on_face, f, np.where(end < 0, e, self.edge[r, e, np.maximum(end, 0)]))
        return dist, np.where(on_face[:, None], point - n * h[:, None], qe), normal, kind, ident

    def crosses(self, p0: np.ndarray, u: np.ndarray) -> np.ndarray:
        """(k,) whether segments p0 + t u, t in [0, 1] ((k, 3) [m]) meet each row's hull
        (Cyrus-Beck: the segment's part inside every face plane is not empty)."""
        lo, hi, blocked = _slab(self.normal, self.offset, p0, u)
        return (lo.max(axis=1, initial=0.0) <= hi.min(axis=1, initial=1.0)) & ~blocked

    def clip_segment(self, face: np.ndarray, p0: np.ndarray, u: np.ndarray):
        """Segments p0 + t u ((k, 3) [m]) cut to the prism over face ``face`` (k,).

        Returns:
            t (k, 2) the ends' parameters; code (k, 2): 0 and 1 for an uncut end, 2 + 2 j
            and 3 + 2 j for an end on side plane j; ok (k,) whether anything is left.
        """
        lo, hi, blocked = _slab(*self.side_planes(face)[:2], p0, u)
        r = np.arange(len(face))
        j0, j1 = np.argmax(lo, axis=1), np.argmin(hi, axis=1)
        t = np.stack([np.maximum(lo[r, j0], 0.0), np.minimum(hi[r, j1], 1.0)], axis=1)
        code = np.stack([np.where(lo[r, j0] > 0.0, 2 + 2 * j0, 0),
                         np.where(hi[r, j1] < 1.0, 3 + 2 * j1, 1)], axis=1)
        return t, code, (t[:, 0] <= t[:, 1]) & ~blocked

    @classmethod
    def boxes(cls, half: np.ndarray) -> HullBatch:
        """Boxes of (k, 3) half extents [m], centred at the origin on the axes."""
        half = np.asarray(half, dtype=np.float64).reshape(-1, 3)
        one = _UNIT_CUBE.batch(np.zeros(len(half), np.int64))
        return HullBatch(one.vertex * half[:, None], one.normal,
                         np.einsum("kfi,ki->kf", np.abs(one.normal), half),
                         one.loop, one.loop_count, one.edge, one.edge_face, one.centre,
                         np.linalg.norm(half, axis=1))


@dataclass(frozen=True)
class HullSet:
    """Several hulls (H of them) as padded arrays; :meth:`batch` picks one per pair.

    Attributes:
        hull_name: (H,) names. hull_vertex: (H, V, 3) [m]; hull_vertex_count: (H,).
        hull_face_normal: (H, F, 3); hull_face_offset: (H, F) [m]; hull_face_count: (H,).
        hull_face_loop: (H, F, L) corner indices; hull_face_loop_count: (H, F).
        hull_edge, hull_edge_face: (H, E, 2); hull_edge_count: (H,).
        hull_centre: (H, 3) [m]; hull_radius: (H,) [m].
    """

    hull_name: tuple[str, ...]
    hull_vertex: np.ndarray
    hull_vertex_count: np.ndarray
    hull_face_normal: np.ndarray
    hull_face_offset: np.ndarray
    hull_face_count: np.ndarray
    hull_face_loop: np.ndarray
    hull_face_loop_count: np.ndarray
    hull_edge: np.ndarray
    hull_edge_face: np.ndarray
    hull_edge_count: np.ndarray
    hull_centre: np.ndarray
    hull_radius: np.ndarray

    @property
    def hull_count(self) -> int:
        return len(self.hull_name)

    @classmethod
    def from_shapes(cls, shapes) -> HullSet:
        """Pad a sequence of :class:`HullShape` into one set (hull i = shapes[i])."""
        shapes = list(shapes)

        def pad(rows, dtype=np.float64):  # one padded array of every shape's rows
            size = max(len(a) for a in rows)
            return frozen(np.stack([_pad(a, size) for a in rows]), dtype)

        lmax = max(int(s.face_loop_count.max()) for s in shapes)
        loops = [np.stack([_pad(s.face_loop[a:a + c], lmax) for a, c in
                           zip(s.face_loop_start, s.face_loop_count)]) for s in shapes]
        count = {k: frozen([len(getattr(s, k)) for s in shapes], np.int64)
                 for k in ("vertex", "face_normal", "edge")}
        return cls(tuple(s.name for s in shapes), pad([s.vertex for s in shapes]),
                   count["vertex"], pad([s.face_normal for s in shapes]),
                   pad([s.face_offset for s in shapes]), count["face_normal"],
                   pad(loops, np.int64), pad([s.face_loop_count for s in shapes], np.int64),
                   pad([s.edge for s in shapes], np.int64),
                   pad([s.edge_face for s in shapes], np.int64), count["edge"],
                   frozen([s.centre for s in shapes]), frozen([s.radius for s in shapes]))

    @classmethod
    def from_ranges(cls, points, start, count, names) -> HullSet:
        """One hull per range of (m, 3) ``points`` [m] (e.g. a model's ``hull_points`` with
        ``body_hull_start``/``body_hull_count`` of its HULL bodies, named by ``names``)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return cls.from_shapes(HullShape.from_points(p[s:s + c], name)
                               for s, c, name in zip(start, count, names))

    def batch(self, index) -> HullBatch:
        """Hulls ``index`` (k,) as a batch, its padding cut to the largest of them."""
        i = np.asarray(index, dtype=np.int64).reshape(-1)
        v = int(self.hull_vertex_count[i].max(initial=1))
        f = int(self.hull_face_count[i].max(initial=1))
        e = int(self.hull_edge_count[i].max(initial=1))
        loop_count = self.hull_face_loop_count[i, :f]
        lmax = int(loop_count.max(initial=1))
        return HullBatch(self.hull_vertex[i, :v], self.hull_face_normal[i, :f],
                         self.hull_face_offset[i, :f], self.hull_face_loop[i, :f, :lmax],
                         loop_count, self.hull_edge[i, :e], self.hull_edge_face[i, :e],
                         self.hull_centre[i], self.hull_radius[i])


def _slab(normal, offset, p0, u):
    """Where segments p0 + t u (k, 3) enter (lo (k, f)) and leave (hi (k, f)) the half-spaces
    normal . x <= offset ((k, f, 3), (k, f)); -inf / inf where a plane does not bound t, and
    blocked (k,) where a parallel segment lies outside one."""
    den = np.einsum("kfi,ki->kf", normal, u)
    num = offset - np.einsum("kfi,ki->kf", normal, p0)
    ratio = num / np.where(den == 0.0, 1.0, den)
    lo, hi = np.where(den < 0.0, ratio, -np.inf), np.where(den > 0.0, ratio, np.inf)
    return lo, hi, ((den == 0.0) & (num < 0.0)).any(axis=1)


def _pad(a: np.ndarray, size: int) -> np.ndarray:
    """``a`` with its first row repeated to ``size`` rows: a repeated corner, face or edge
    changes no support point, minimum or maximum; loops beyond their counts are never read."""
    a = np.asarray(a)
    return np.concatenate([a, np.repeat(a[:1], size - len(a), axis=0)])


_UNIT_CUBE = HullSet.from_shapes([HullShape.from_points(
    [[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)], "box")])
