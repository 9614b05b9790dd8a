"""Any triangle mesh as a collider: moving, rotating and deforming, open or closed.

The mesh lives in its object's local frame like the analytic shapes (see :mod:`.path`):
a particle's path is tested as the local segment l0 = M(s0)^-1 x0 -> l1 = M(s1)^-1 x1. Its local
vertices move linearly over the frame interval, vertices(s) = lerp(vertices0, vertices1, s); one
bounding-volume hierarchy is built per interval and refitted for the sub-step times.

Two tests together leave no way through a thin, single-sided mesh:

* fast particles: the exact segment-triangle test (:func:`~..collision.raycast.segment_hits`) of
  the local segment against the mesh at s1 — watertight, a segment cannot slip through a shared
  edge, and it hits either face;
* a mesh moving over slow particles (deforming, or rotating so that the local path is a curve
  rather than the segment): side tracking. For particles near the mesh, the side of the surface
  at s0 (against the mesh at s0) is compared with the side at s1 (against the mesh at s1); the
  side is the sign of (l - closest point) . n with n the closest triangle's winding normal, which
  is defined for open single-sided meshes too. A side change without a segment hit is a crossing
  caused by the mesh: it is reported as a hit at t = 1 on the s1 closest point, its normal
  pointing back to the original side. Near an open boundary (the closest point on a boundary
  edge or corner) a particle may pass around the mesh, so no side is taken there.

Thickness: the segment tests use the surface proper and a point placed on it is moved
``thickness`` out along the normal (:attr:`ColliderPath.offset`); an end point closer to the
surface than ``thickness`` counts as a hit at t = 1. Distances are measured in the local frame
and mapped to world lengths, which is exact for rotations and uniform scales (and close for
moderate non-uniform ones).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..collision.bvh import BVH
from ..collision.crossing import barycentric
from ..collision.distance import closest_on_triangles, closest_points
from ..collision.raycast import segment_hits
from ..transforms import (cross, divide_rows, inverse_affine, norm_rows, scale_rows, take,
                          transform_vectors, where_rows)
from .frame import ColliderFrame
from .mesh_hierarchies import BVH_KIND, REBUILD_AFTER, MeshHierarchies  # noqa: F401 (theirs)
from .path import (CONTACT_DISTANCE, ColliderPath, Features, Hits, SurfacePoints, padded_box,
                   rows_meeting, same_times, times_of)

EPS = float(np.finfo(np.float64).eps)
BVH_CACHE = 8  # hierarchies kept per interval (refits for the sub-step times in use)


class MeshPath(ColliderPath):
    """A triangle mesh collider during one frame interval; its hierarchy comes from (and is kept
    for the next interval by) ``hierarchies``, which the caller owns.

    Attributes:
        vertex_step: (n, 3) local vertex displacement over the interval [local units].
        deforming: whether any vertex moves in the local frame.
        max_step: largest vertex displacement over the interval [local units].
    """

    def __init__(self, frame: ColliderFrame, frame_dt: float, hierarchies: MeshHierarchies):
        super().__init__(frame, frame_dt)
        self.offset = frame.thickness
        self.triangles = frame.triangles
        self.vertices0 = frame.vertices0
        if frame.vertices1 is frame.vertices0:  # (one shape: a rigid body's, a still mesh's)
            self.vertex_step = np.broadcast_to(0.0, frame.vertices0.shape)
        else:
            self.vertex_step = frame.vertices1 - frame.vertices0
        self.deforming = bool(np.any(self.vertex_step))
        # hits are found on the mesh as it is at the sub-step's end (see response.respond)
        self.hits_end_surface = self.deforming
        self.max_step = float(norm_rows(self.vertex_step).max()) if self.deforming else 0.0
        self._bvh0, self._boundary = hierarchies.of(frame)
        # a grid for the many short queries of particles on a mesh that keeps its shape
        self._cells = None if self.deforming else hierarchies.cells(frame.name, self._bvh0)
        self._welded = self._bvh0.mesh.welded_corners  # corners, duplicates merged
        self._bvhs: dict[float, BVH] = {}
        if self.deforming:
            both = np.concatenate([frame.vertices0, frame.vertices1])
            self._lo, self._hi = both.min(axis=0), both.max(axis=0)
        else:  # the hierarchy's mesh has exactly these vertices
            self._lo, self._hi = self._bvh0.mesh.bounds
        # the most local units a world metre can span over the interval (distance conversions):
        # the inverse's largest stretch (its rows' largest length falls short under a shear)
        self._local_metre = max(float(np.linalg.norm(inverse_affine(m)[:3, :3], 2))
                                for m in self.path.samples)
        self._still = self.still
        self._box = None  # see _world_box
        # a mesh standing still is a function of its frame: the next interval of the same
        # frame can use this path (and its hierarchy and grid) again
        self.reusable = self._still

    # -- geometry at a time s ---------------------------------------------------------------------
    def bvh_at(self, s: float) -> BVH:
        """The hierarchy over the mesh at parameter s (refitted from the interval's start)."""
        s = float(s)
        if not self.deforming or s == 0.0:
            return self._bvh0
        bvh = self._bvhs.get(s)
        if bvh is None:
            if len(self._bvhs) >= BVH_CACHE:
                self._bvhs.clear()
            bvh, _ = self._bvh0.refit(self.vertices0 + s * self.vertex_step)
            self._bvhs[s] = bvh
        return bvh

    def features(self, s0: float, s1: float) -> Features:
        """The mesh's creases (:attr:`~..collision.mesh.TriangleMesh.creases`) and their ends."""
        edges, corners = self._bvh0.mesh.creases
        if not len(edges):
            return Features.none()

        def at(s: float) -> np.ndarray:
            return self.vertices0 + s * self.vertex_step if self.deforming else self.vertices0

        v0, v1 = at(s0), at(s1)
        return Features(v0[corners], v1[corners], np.zeros(len(corners)), v0[edges], v1[edges])

    def _corners(self, tri: np.ndarray, s: np.ndarray) -> np.ndarray:
        """(k, 3, 3) corners of triangles ``tri`` (k,) at per-triangle parameters s (k,)."""
        ids = self.triangles[tri]
        return self.vertices0[ids] + np.asarray(s, float).reshape(-1, 1, 1) * self.vertex_step[ids]

    def _closest(self, l: np.ndarray, s: np.ndarray, reach):
        """Closest points of local points l (k, 3) on the mesh at their times s (k,), within
        ``reach`` (one for all, or (k,) one each).

        Returns (found, point, diff = l - point, distance, face normal, triangle, side,
        outside, outward): side is +1/-1 in front of/behind the nearest triangle's face (what
        a contact normal faces: :meth:`_facing`), outside +1/-1 in front of/behind the surface
        around the nearest feature, judged by its angle-weighted pseudo-normal ``outward``
        (what side tracking compares: by the nearest triangle's own face, a point off an
        acute edge of a closed mesh is behind one of its faces, metres outside it); both 0
        where not found, on the surface, or nearest to an open boundary edge or corner. At
        per-point times on a deforming mesh both are the face's.
        """
        values = np.unique(s)
        bvh = self.bvh_at(values[-1])
        cp = closest_points(bvh, l, max_distance=np.maximum(reach, 1e-300), cells=self._cells)
        found = cp.triangle >= 0
        tri = np.where(found, cp.triangle, 0)
        q, feature = cp.point, cp.feature
        one_time = not (len(values) > 1 and self.deforming)
        if not one_time:
            # per-point times (re-tests after a hit): the triangle found at the latest time,
            # evaluated at each point's own time
            corners = self._corners(tri, s)
            q, _, feature = closest_on_triangles(l, corners)
        else:
            corners = take(bvh.mesh.triangle_vertices, tri)
        face = cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        divide_rows(face, np.maximum(norm_rows(face), 1e-300), out=face)
        diff = l - q
        dist = norm_rows(diff)
        feature = np.maximum(feature, 0)
        valid = found & ~self._boundary[tri, feature]
        side = np.where(valid, np.sign(np.einsum("ij,ij->i", diff, face)), 0.0)
        outside, outward = side, face
        if one_time:  # (the pseudo-normals are the mesh's at that one time)
            outward = take(bvh.mesh.feature_normals, 7 * tri + feature)
            outside = np.where(valid, np.sign(np.einsum("ij,ij->i", diff, outward)), 0.0)
        return found, q, diff, dist, face, tri, side, outside, outward

    def _touching(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(k,) whether triangles a and b are the same or share a (welded) corner."""
        w = self._welded
        return np.any(w[a][:, :, None] == w[b][:, None, :], axis=(1, 2))

    @staticmethod
    def _facing(diff, dist, face, side, prefer) -> np.ndarray:
        """Local unit normals facing the query points: the face normal turned to ``side`` (or
        ``prefer`` where the side is undefined); beside an open boundary, the direction from
        the closest point to the query point."""
        sign = np.where(side != 0.0, side, prefer)
        n = scale_rows(face, sign)
        around = (side == 0.0) & (dist > 0.0)
        if not around.any():
            return n
        return where_rows(around, divide_rows(diff, np.where(around, dist, 1.0)), n)

    def _world_length(self, vec: np.ndarray, s) -> np.ndarray:
        lin = self._at(s)[..., :3, :3]
        return norm_rows(transform_vectors(lin, vec))

    def _near_box(self, lo: np.ndarray, hi: np.ndarray, reach) -> np.ndarray:
        """Indices of boxes [lo, hi] (k, 3) within ``reach`` of the mesh's interval bounds."""
        r = np.broadcast_to(np.asarray(reach, float), (len(lo),))
        near = np.ones(len(lo), bool)
        for j in range(3):  # by columns: numpy broadcasts over (k, 3) row by row
            near &= (lo[:, j] <= self._hi[j] + r) & (hi[:, j] >= self._lo[j] - r)
        return np.nonzero(near)[0]

    # -- the three questions --------------------------------------------------------------------
    def _world_box(self) -> tuple[np.ndarray, np.ndarray] | None:
        """A still mesh's world box holding every point its questions can answer for: its
        local bounds grown by the thickness and the contact distance (in the most local units
        a metre spans), mapped to the world and padded against rounding; None for a moving or
        deforming mesh. Worked out once."""
        if not self._still:
            return None
        if getattr(self, "_box", None) is None:
            self._box = self._box_at(self.path.m0)
        return self._box

    def _metre(self, s0: float, s1: float) -> float:
        """The most local units a world metre spans over the interval's samples and at the
        times ``s0`` and ``s1`` (an animation whose scale passes zero between its samples spans
        more between them); worked out once per pair of times."""
        known = self.__dict__.setdefault("_metres", {})
        metre = known.get((s0, s1))
        if metre is None:
            metre = known[(s0, s1)] = max(
                self._local_metre, *(float(np.linalg.norm(self._inverse(s)[:3, :3], 2))
                                     for s in (s0, s1)))
        return metre

    def _box_at(self, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The world box of the mesh's local bounds (over the interval: a deforming mesh's
        vertices at both ends) grown by the thickness and the contact distance, under the
        matrix ``m``."""
        reach = (self.frame.thickness + CONTACT_DISTANCE) * self._local_metre * (1.0 + 1e-9)
        half = np.abs(m[:3, :3]) @ ((self._hi - self._lo) / 2.0 + reach)
        return padded_box(m[:3, :3] @ ((self._hi + self._lo) / 2.0) + m[:3, 3], half)

    def world_cut(self, distance: float, far: float, s=None, sweep: tuple | None = None
                  ) -> tuple | None:
        """A still mesh's world box (:meth:`_world_box`: its own cut, for every question,
        which holds the contact distance), or a moving or deforming one's at one time ``s``
        (points asked at that time: :meth:`_near_rows`); None for other times, or asked for
        more than the contact distance."""
        if distance > CONTACT_DISTANCE:
            return None
        if self._still:
            return self._world_box()
        if s is None:
            return None if sweep is None or distance or not far < np.inf else \
                self._sweep_box(*sweep, far)
        return self._box_at(self._at(s))

    def _sweep_box(self, s0: float, s1: float, length: float, far: float) -> tuple | None:
        """A moving or deforming mesh's world cut of segments from time s0 to s1
        (:meth:`ColliderPath._swept_box` of its local bounds over the interval grown by the
        thickness and the contact distance, as :meth:`_box_at`, and by what the maps may round
        to over points up to ``far``): a segment that enters it or ends within its thickness
        has a local point there, and so has a particle the mesh passed over (its side changed:
        it ends inside a closed mesh, or crossed an open sheet's faces; sides are judged by
        pseudo-normals, so outside that box a consistent mesh has no side change without a
        crossing). A triangle soup with faces wound every which way can change a far point's
        side without one: that spurious hit, beyond the box, is the one answer the cut drops."""
        local = self._local_far(far, s0, s1)
        metre = self._metre(s0, s1)
        grow = (self.frame.thickness + CONTACT_DISTANCE) * metre * (1.0 + 1e-9)
        return self._swept_box(s0, s1, (self._hi + self._lo) / 2.0,
                               (self._hi - self._lo) / 2.0 + grow + 64.0 * EPS * local, length)

    def _near_rows(self, *points: np.ndarray, s: float | None = None) -> np.ndarray | None:
        """The rows of ``points`` (their box over the arrays) within a still mesh's world box
        (:meth:`_world_box`), or with ``s`` (points at that one time) within the world box
        of a moving or deforming mesh at s; None where every row is (or there is no such
        box)."""
        box = self._world_box() if s is None or self._still else self._box_at(self._at(s))
        return None if box is None else rows_meeting(*box, *points)

    def first_hits(self, start, end, s_start, s_end) -> Hits:
        """Segment hits on the mesh at the end times, kept where the segment came from the side
        it hits; then the hits at t = 1 that the segment test cannot see (see the module). Of a
        still mesh, only the segments whose box meets its world box are tested."""
        sub = self._near_rows(start, end) if self._still else \
            self.sweep_rows(start, end, s_start, s_end)
        if sub is not None:
            if not len(sub):
                return Hits.none()
            return self._first_hits(take(start, sub), take(end, sub), times_of(s_start, sub),
                                    times_of(s_end, sub)).of_rows(sub)
        return self._first_hits(start, end, s_start, s_end)

    def _first_hits(self, start, end, s_start, s_end) -> Hits:
        if len(end) == 0:
            return Hits.none()
        l0 = self.to_local(start, s_start)
        l1 = self.to_local(end, s_end)
        thick = self.frame.thickness * self._local_metre
        reach = (norm_rows(l1 - l0) + self.max_step * np.abs(s_end - s_start) + thick
                 + CONTACT_DISTANCE * self._local_metre)
        cand = self._near_box(np.minimum(l0, l1), np.maximum(l0, l1), reach)
        if len(cand) == 0:
            return Hits.none()
        # (each segment's own reach bounds its searches: the largest of them all made every
        # search as wide as the fastest particle's)
        l0, l1, sa, sb, r = l0[cand], l1[cand], s_start[cand], s_end[cand], reach[cand]
        entries = self._segment_entries(l0, l1, sb)
        side0 = tri0 = outside0 = None
        if not self._still:
            _, _, _, _, _, tri0, side0, outside0, _ = self._closest(l0, sa, r)
        if self.deforming and entries.hit.any():
            self._drop_entries_from_behind(entries, l0, sa, tri0, side0)
        if not (self._still and self.frame.thickness == 0.0):
            self._late_entries(entries, l1, sb, r, outside0)
        return entries.hits(cand)

    def _segment_entries(self, l0: np.ndarray, l1: np.ndarray, sb: np.ndarray) -> _Entries:
        """Fast particles: exact segment-triangle tests of local segments l0 -> l1 (k, 3) on the
        mesh at their end times sb (k,)."""
        k = len(l0)
        found = _Entries(np.zeros(k, bool), np.ones(k), np.zeros((k, 3)), np.zeros((k, 3)),
                         np.full(k, -1, np.int64), np.zeros(k, bool))
        for s in np.unique(sb):
            g = np.nonzero(sb == s)[0]
            sh = segment_hits(self.bvh_at(s), l0[g], l1[g], cells=self._cells)
            # a segment starting on the surface has no side to come from: it counts as coming
            # from the front (as contacts do), so only moving into the back is a hit
            found.hit[g] = sh.hit & ~((sh.t == 0.0) & ~sh.front)
            found.normal[g], found.point[g] = sh.normal, sh.point
            found.triangle[g], found.front[g] = sh.triangle, sh.front
            found.t[g] = np.where(sh.hit, sh.t, 1.0)
        return found

    def _drop_entries_from_behind(self, found: _Entries, l0: np.ndarray, sa: np.ndarray,
                                  tri0: np.ndarray, side0: np.ndarray) -> None:
        """The segment is tested against the mesh at the end time: a particle riding a deforming
        surface crosses where that surface will be from behind. Such a hit is real only if the
        particle started (at sa, nearest triangles tri0 on sides side0) on the side it hits
        from; otherwise the surface moved past it and side tracking decides. The side is judged
        on the mesh at the start time nearest the particle when that is the triangle hit or one
        touching it (across a ridge the hit triangle's plane may pass on the wrong side of a
        particle sitting on its neighbour); otherwise — another sheet of the mesh, or no side
        (an open boundary) — on the hit triangle's own plane. Modifies ``found`` in place."""
        g = np.nonzero(found.hit)[0]
        c = self._corners(found.triangle[g], sa[g])
        face = cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
        plane = np.sign(np.einsum("ij,ij->i", l0[g] - c[:, 0], face))
        near = (side0[g] != 0.0) & self._touching(tri0[g], found.triangle[g])
        side = np.where(near, side0[g], plane)
        found.hit[g[side * np.where(found.front[g], 1.0, -1.0) < 0.0]] = False

    def _late_entries(self, found: _Entries, l1: np.ndarray, sb: np.ndarray, r: np.ndarray,
                      outside0: np.ndarray | None) -> None:
        """Hits at t = 1 on the end-time surface, for segments ``found`` did not hit: the mesh
        moved over the particle (its side changed from outside0), or the particle ended within
        the thickness (out to the grown surface). Modifies ``found`` in place."""
        k = len(l1)
        f1, q1, diff1, d1, face1, tri1, side1, outside1, outward1 = self._closest(l1, sb, r)
        late = np.zeros(k, bool)
        late_n = np.zeros((k, 3))
        if not self._still:  # the mesh moving over a particle: a side change without a hit
            # (judged by the surface around each nearest feature, not by the nearest
            # triangle's own face: a particle flying past an acute edge of a closed mesh,
            # metres outside it, changed sides by those)
            crossed = ~found.hit & (outside0 * outside1 < 0.0)
            late |= crossed
            # facing the side it came from: the nearest face turned outward, times that side
            # (a face of no area: the surface's own outward normal there)
            c = np.nonzero(crossed)[0]
            turn = np.sign(np.einsum("ij,ij->i", face1[c], outward1[c]))
            late_n[c] = np.where((turn != 0.0)[:, None], face1[c] * (turn * outside0[c])[:, None],
                                 outward1[c] * outside0[c, None])
        if self.frame.thickness > 0.0:  # ends within the thickness: out to the grown surface
            near = ~found.hit & ~late & f1
            near[near] = self._world_length(diff1[near], sb[near]) < self.frame.thickness
            late |= near
            late_n[near] = self._facing(diff1[near], d1[near], face1[near], side1[near], 1.0)
        found.normal[late], found.point[late] = late_n[late], q1[late]
        found.triangle[late], found.t[late] = tri1[late], 1.0
        found.hit[late] = True

    def push_out(self, x, s, start, s_start) -> SurfacePoints:
        """A thin mesh has no inside: points whose last path start -> x still hits the mesh
        (the passes ran out) are put back on the side they came from, at the hit point on the
        mesh at s (segment hits and side tracking both report points on that mesh)."""
        hits = self.first_hits(start, x, s_start, s)
        idx = hits.index
        if len(idx) == 0:
            return SurfacePoints.none()
        p_w, n_w = self.to_world(hits.point, hits.normal, s[idx])
        gap = np.einsum("ij,ij->i", x[idx] - p_w, n_w) - self.frame.thickness
        velocity = self.surface_velocity(hits.point, s[idx], hits.element)
        return SurfacePoints(idx, p_w, n_w, velocity, gap)

    def near_surface(self, x, s) -> SurfacePoints:
        sub = self._near_rows(x, s=s)  # only the points within its world box at s
        if sub is not None:
            if not len(sub):
                return SurfacePoints.none()
            return self._near_surface(take(x, sub), s).of_rows(sub)
        return self._near_surface(x, s)

    def _near_surface(self, x, s) -> SurfacePoints:
        if len(x) == 0:
            return SurfacePoints.none()
        s = same_times(s, len(x))
        l = self.to_local(x, s)
        within = self.frame.thickness + CONTACT_DISTANCE
        reach = within * self._local_metre * (1.0 + 1e-9)
        cand = self._near_box(l, l, reach)
        if len(cand) == 0:
            return SurfacePoints.none()
        found, q, diff, dist, face, tri, side, _, _ = self._closest(l[cand], s[cand], reach)
        n_local = self._facing(diff, dist, face, side, 1.0)
        p_w, n_w = self.to_world(q, n_local, s[cand])
        gap = np.einsum("ij,ij->i", x[cand] - p_w, n_w) - self.frame.thickness
        keep = found & (np.abs(gap) < CONTACT_DISTANCE)
        sel = np.nonzero(keep)[0]
        velocity = self.surface_velocity(q[sel], s[cand][sel], tri[sel])
        return SurfacePoints(cand[sel], p_w[sel], n_w[sel], velocity, gap[sel])

    @classmethod
    def build(cls, frame: ColliderFrame, frame_dt: float, owner) -> MeshPath:
        return cls(frame, frame_dt, owner.hierarchies)

    def surface_velocity(self, l, s, element=None) -> np.ndarray:
        s = np.broadcast_to(np.asarray(s, float), len(l))
        local_v = None
        if self.deforming and element is not None and len(l):
            el = np.maximum(element, 0)
            w = barycentric(l, self._corners(el, s))
            local_v = np.einsum("nk,nkj->nj", w, self.vertex_step[self.triangles[el]])
            local_v /= self.frame_dt
        if local_v is None and self.path.static:
            return np.zeros_like(l)
        return self.path.point_velocities(l, s, self.frame_dt, local_velocity=local_v)


class _Entries(NamedTuple):
    """Where k candidate segments enter the mesh, in its local frame; the passes of
    :meth:`MeshPath.first_hits` fill the arrays in place."""

    hit: np.ndarray  # (k,) bool
    t: np.ndarray  # (k,) fraction of the segment before the hit
    normal: np.ndarray  # (k, 3) unit normals facing the side the segment came from
    point: np.ndarray  # (k, 3) hit points on the surface proper
    triangle: np.ndarray  # (k,) int64 triangle hit, -1 where none
    front: np.ndarray  # (k,) bool: entered through the winding normal's side

    def hits(self, cand: np.ndarray) -> Hits:
        """The segments that hit, as :class:`Hits` of the segments ``cand`` indexes."""
        hit = self.hit
        return Hits(cand[hit], self.t[hit], self.normal[hit], self.point[hit], self.triangle[hit])
