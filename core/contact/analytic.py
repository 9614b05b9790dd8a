"""Analytic colliders: Blender's default primitives (ground, bounded plane, sphere, box) in their
object's local space, grown by the collider's thickness, with closed-form segment entry, closest
point and inside tests. Vectorised over points."""
from __future__ import annotations

import numpy as np

from ..transforms import rows_at, take
from .frame import ColliderFrame
from .analytic_shapes import closest, inside, segment_hit, shape_features
from .path import (CONTACT_DISTANCE, ColliderPath, Features, Hits, SurfacePoints, farthest,
                   padded_box, rows_meeting, times_of)

SHAPES = ("HALF_SPACE", "PLANE", "SPHERE", "BOX")
EPS = float(np.finfo(np.float64).eps)


class AnalyticPath(ColliderPath):
    """A unit shape (see :class:`ColliderFrame`) grown by the collider's thickness.

    Attributes:
        extent: (3,) the shape's extent in local units, thickness included (see below).
    """

    reusable = True

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
        self._features = shape_features(frame.shape, extent)
        self._z_row = None  # see _plane_z
        self._box = None  # see _bounds

    def first_hits(self, start, end, s_start, s_end) -> Hits:
        shape = self.frame.shape
        cand = self._segment_candidates(start, end, s_start, s_end)
        if cand is None:  # a moving sphere or box: the segments that meet its world box
            # over their time (:meth:`_sweep_box`) in its local space, then only those whose
            # local box meets the shape's are tested (a segment that enters the shape, or ends
            # in it, has a point in that box)
            near = self.sweep_rows(start, end, s_start, s_end)
            if near is not None:
                if not len(near):
                    return Hits.none()
                start, end = take(start, near), take(end, near)
                s_start, s_end = times_of(s_start, near), times_of(s_end, near)
            l0, l1 = self.to_local(start, s_start), self.to_local(end, s_end)
            cand = self._local_rows(np.zeros(3), l0, l1)
            if cand is None:
                cand = np.arange(len(end))
            else:
                l0, l1 = take(l0, cand), take(l1, cand)
            if near is not None:
                cand = near[cand]
        elif len(cand):
            l0 = self.to_local(start[cand], s_start[cand])
            l1 = self.to_local(end[cand], s_end[cand])
        if len(cand) == 0:
            return Hits.none()
        hit, t, n_local = segment_hit(shape, l0, l1, self.extent)
        l_hit = l0 + t[:, None] * (l1 - l0)
        # a collider that moved onto a particle: push it out to the nearest surface point
        stuck = ~hit & inside(shape, l1, self.extent)
        if stuck.any():
            p, n_in, _ = closest(shape, l1[stuck], self.extent)
            l_hit[stuck] = p
            n_local[stuck] = n_in
            t = np.where(stuck, 1.0, t)
            hit = hit | stuck
        return Hits(cand[hit], t[hit], n_local[hit], l_hit[hit])

    def _sweep_box(self, s0: float, s1: float, length: float, far: float) -> tuple | None:
        """A moving sphere's or box's world cut of segments from time s0 to s1
        (:meth:`ColliderPath._swept_box` of its local box, padded by what its tests may round
        to over points up to ``far``)."""
        local = self._local_far(far, s0, s1)
        half = self.extent + (self._rounding(local) + 64.0 * EPS * local)
        return self._swept_box(s0, s1, np.zeros(3), half, length)

    def push_out(self, x, s, start, s_start) -> SurfacePoints:
        # only points within a sphere's or box's world box (a still one's, or a moving one's
        # at s) can be in it
        sub = self._within(0.0, x) if self.path.static or self.frame.shape not in (
            "SPHERE", "BOX") else self._moving_rows(x, s, np.zeros(3))
        if sub is not None:
            x, s = take(x, sub), take(s, sub)
        l = self.to_local(x, s)
        within = inside(self.frame.shape, l, self.extent)
        if not within.any():
            return SurfacePoints.none()
        idx = np.nonzero(within)[0]
        p, n_local, _ = closest(self.frame.shape, l[idx], self.extent)
        p_w, n_w = self.to_world(p, n_local, s[idx])
        gap = np.einsum("ij,ij->i", x[idx] - p_w, n_w)
        return SurfacePoints(idx if sub is None else sub[idx], p_w, n_w,
                             self.surface_velocity(p, s[idx]), gap)

    def near_surface(self, x, s) -> SurfacePoints:
        shape = self.frame.shape
        if shape in ("HALF_SPACE", "PLANE"):
            return self._near_plane(x, s)
        return self._near_closest(x, s)

    def _near_closest(self, x, s) -> SurfacePoints:
        """:meth:`near_surface` through each point's closest surface point in local space (any
        shape; ``s`` a scalar or one parameter per point); of a still sphere or box, only for
        the points within its world box grown by the contact distance (see :meth:`_bounds`)."""
        sub = self._within(CONTACT_DISTANCE, x) if self.path.static else self._near_moving(x, s)
        if sub is not None:
            if not len(sub):
                return SurfacePoints.none()
            return self._near_closest_all(take(x, sub), s if np.ndim(s) == 0 else
                                          take(np.asarray(s), sub)).of_rows(sub)
        return self._near_closest_all(x, s)

    def _near_moving(self, x, s) -> np.ndarray | None:
        """A moving sphere's or box's cut for :meth:`near_surface`: the rows of the points
        ``x`` within its :meth:`world_cut` for the contact distance at their one time ``s``;
        None where the points' times differ, or every row is within."""
        cut = self.world_cut(CONTACT_DISTANCE, 0.0, s)
        return None if cut is None else rows_meeting(*cut, x)

    def _moving_rows(self, x, s, grow: np.ndarray) -> np.ndarray | None:
        """The rows of a moving sphere's or box's points ``x`` at one ``s`` (scalar, or the same
        for every point) within the world box of its local box (its extent, which holds a
        sphere too) grown by ``grow`` (3,) at ``s``: every point whose local point lies in that
        grown box. None where the points' times differ, or every row is within."""
        box = self._moving_box(s, grow)
        return None if box is None else rows_meeting(*box, x)

    def _moving_box(self, s, grow: np.ndarray) -> tuple | None:
        """The world box at one ``s`` of a moving sphere's or box's local box (its extent)
        grown by ``grow`` (3,), padded against rounding; None where ``s`` is several times."""
        m = self._at(s)
        if m.ndim != 2:
            return None
        return padded_box(m[:3, 3], np.abs(m[:3, :3]) @ (self.extent + grow))

    def _local_rows(self, grow: np.ndarray, *local: np.ndarray) -> np.ndarray | None:
        """The rows whose local points (their box over the arrays) meet the shape's local box
        (its extent, which holds a sphere too) grown by ``grow`` (3,) and padded against
        rounding: relatively, and by what the shape's own tests may round to over the farthest
        point asked (a sphere's discriminant by about eps |l|^2: a long segment grazing it may
        be found to touch it); None where every row meets it, or a point is not finite."""
        far = farthest(*local)
        if not far < np.inf:  # (NaN too): the shape's tests answer for every row
            return None
        lo, hi = padded_box(np.zeros(3), self.extent + grow + self._rounding(far))
        return rows_meeting(lo, hi, *local)

    def _rounding(self, far: float) -> float:
        """How far off the shape (local units) its tests may find a point or segment touching
        it by rounding, for points up to ``far`` along any local axis: a sphere's
        discriminant rounds by about eps |l|^2 (|l|^2 <= 3 far^2), with a margin."""
        return 32.0 * EPS * 3.0 * far * far / float(self.extent.min())

    def _near_closest_all(self, x, s) -> SurfacePoints:
        l = self.to_local(x, s)
        p, n_local, valid = closest(self.frame.shape, l, self.extent)
        p_w, n_w = self.to_world(p, n_local, s)
        d = np.einsum("ij,ij->i", x - p_w, n_w)
        near = np.nonzero(valid & (d > -CONTACT_DISTANCE) & (d < CONTACT_DISTANCE))[0]
        s_near = s if np.ndim(s) == 0 else np.asarray(s)[near]
        return SurfacePoints(near, p_w[near], n_w[near], self.surface_velocity(p[near], s_near),
                             d[near])

    def _near_plane(self, x, s) -> SurfacePoints:
        """:meth:`near_surface` of the ground and a bounded plane. An affine map keeps planes
        flat, so a point's world distance to the plane z = c (local) is (z - c) / |grad z|
        with grad z the inverse matrix's third row, and its closest point lies along that
        gradient: one row of the inverse for every point, the rest only for the near ones."""
        inv = self._inverse(s)
        if inv.ndim == 3:  # per-point times: the general route
            return self._near_closest(x, s)
        grad = inv[2, :3]
        scale = float(np.linalg.norm(grad))
        z = self._local_z(x, s)
        e = self.extent
        plane = self.frame.shape == "PLANE"
        d = ((np.abs(z) if plane else z) - e[2]) / scale
        cand = np.nonzero(np.abs(d) < CONTACT_DISTANCE)[0]
        xc = rows_at(x, cand)
        if plane:  # off its edges nothing rests on it
            lx, ly = _affine_row(xc, inv[0]), _affine_row(xc, inv[1])
            inside = (np.abs(lx) <= e[0]) & (np.abs(ly) <= e[1])
            if not inside.all():
                cand = cand[inside]
                xc = xc[inside]
        if len(cand) == 0:
            return SurfacePoints.none()
        d = rows_at(d, cand)
        normal = grad / scale
        n_w = np.tile(normal, (len(cand), 1))  # (a broadcast fill of (k, 3) rows: 2 x slower)
        sides = 1.0
        if plane:  # the side each point is on
            below = rows_at(z, cand) < 0.0
            if below.any():
                n_w[below] *= -1.0
                sides = -1.0 if below.all() else 0.0
        along = np.nonzero(normal)[0]
        axis = None
        if self.path.static and sides and len(along) == 1 and abs(normal[along[0]]) == 1.0:
            axis = (int(along[0]), float(sides * normal[along[0]]))
            p_w = xc.copy()  # the same values: the other columns move by d * 0
            p_w[:, axis[0]] -= d * axis[1]
        else:
            p_w = xc - d[:, None] * n_w
        velocity = (np.zeros_like(p_w) if self.path.static else
                    self.surface_velocity(self.to_local(p_w, s), s))
        return SurfacePoints(cand, p_w, n_w, velocity, d, axis)

    def apart(self, points: tuple, s: float, distance: float) -> bool:
        """:meth:`ColliderPath.apart` of a ground or bounded plane standing still: the local
        z range of the points (z is affine, so the points' hull lies within it), as far from
        the surface as the nearest point. The same comparisons as :meth:`_near_plane` and
        :meth:`first_hits` make of each point (their roundings are monotone in z), so where
        this says apart they find nothing."""
        shape = self.frame.shape
        if not self.path.static or shape not in ("HALF_SPACE", "PLANE"):
            return False
        row, k, scale = self._plane_z()
        plane = shape == "PLANE"
        lo, hi = np.inf, -np.inf
        for x in points:
            if len(x):
                a, b = _affine_range(x, row, k, plane)
                if a != a or b != b:  # NaN: the questions answer for it
                    return False
                lo, hi = min(lo, a), max(hi, b)
        level = self.extent[2]
        return bool((lo - level) / scale >= distance or
                    plane and (-hi - level) / scale >= distance)

    def _plane_z(self) -> tuple:
        """The local z of the collider at rest: its row of the inverse, the one axis it reads
        (or -1) and its gradient's length (world distance = (z - level) / length); worked out
        once (a path saved before it was kept works it out when first asked)."""
        if getattr(self, "_z_row", None) is None:
            row = self._inverse0[2]
            axes = np.nonzero(row[:3])[0]
            self._z_row = (row, int(axes[0]) if len(axes) == 1 else -1,
                           float(np.linalg.norm(row[:3])))
        return self._z_row

    def _bounds(self) -> tuple | None:
        """A still sphere's or box's world box (lo, hi), and how far (as a multiple of a
        distance) a point :meth:`near_surface` finds may lie outside it; None for grounds,
        planes and moving colliders. Near is judged along the normal of a supporting plane,
        which a non-uniform scale tilts: a point found within d of it lies within d times the
        matrix's condition number of the shape. Padded against rounding; worked out once."""
        if self.frame.shape not in ("SPHERE", "BOX") or not self.path.static:
            return None
        if getattr(self, "_box", None) is None:
            m, e = self.path.m0[:3, :3], self.extent
            # the world extent of a ball (an ellipsoid's: e0 times each row's length) or of a
            # box (each row's absolute values against the half extents)
            half = e[0] * np.linalg.norm(m, axis=1) if self.frame.shape == "SPHERE" \
                else np.abs(m) @ e
            stretch = np.linalg.svd(m, compute_uv=False)
            self._box = (*padded_box(self.path.m0[:3, 3], half),
                         float(stretch[0] / stretch[-1]) * (1.0 + 1e-9))
        return self._box

    def _within(self, distance: float, *points: np.ndarray) -> np.ndarray | None:
        """The rows whose points (their box, over several arrays: segments) come within
        ``distance`` (scaled as :meth:`_bounds` says) of a still sphere's or box's world box;
        None where every row may (or there is no such box)."""
        far = farthest(*points)
        if not far < np.inf:  # (NaN too): the shape's tests answer for every row
            return None
        cut = self.world_cut(distance, far)
        return None if cut is None else rows_meeting(*cut, *points)

    def world_cut(self, distance: float, far: float, s=None, sweep: tuple | None = None
                  ) -> tuple | None:
        """A still sphere's or box's world box (:meth:`_bounds`) grown by ``distance`` (scaled
        as it says) and by what the shape's tests may round to over a point ``far`` from the
        origin: in local units the point lies within sqrt(3) (far + |origin|) / least
        stretch, and a local length maps to at most sqrt(3) times the largest stretch along a
        world axis. A moving one's at one time ``s`` (points asked at that time): the world
        box of its local box (its extent, which holds a sphere too) grown, in its own units,
        by the distance times the matrix's condition number (a point found within it of the
        surface lies within that of the shape; bounded here by the product of the matrix's
        and its inverse's Frobenius norms) along each local axis, as far as a world metre
        spans there (its inverse's row length). A moving one's for segments over a ``sweep``
        entering it (``distance`` 0): :meth:`_sweep_box`. None for other colliders and times."""
        if not self.path.static:
            if self.frame.shape not in ("SPHERE", "BOX"):
                return None
            if s is None:
                return None if sweep is None or distance or not far < np.inf else \
                    self._sweep_box(*sweep, far)
            m = self._at(s)
            if m.ndim != 2:
                return None
            inv3 = self._inverse(s)[:3, :3]
            condition = float(np.linalg.norm(m[:3, :3]) * np.linalg.norm(inv3))
            grow = distance * condition * np.linalg.norm(inv3, axis=1) * (1.0 + 1e-9)
            return self._moving_box(s, grow)
        bounds = self._bounds()
        if bounds is None or not far < np.inf:
            return None
        lo, hi, factor = bounds
        big, small = self._stretches()
        origin = float(np.abs(self.path.m0[:3, 3]).max())
        grow = distance * factor + 2.0 * big * self._rounding((far + origin) / small)
        return lo - grow, hi + grow

    def _stretches(self) -> tuple[float, float]:
        """A still shape's matrix's largest and least stretch (singular values), worked out
        once."""
        if getattr(self, "_singular", None) is None:
            stretch = np.linalg.svd(self.path.m0[:3, :3], compute_uv=False)
            self._singular = (float(stretch[0]), float(stretch[-1]))
        return self._singular

    def features(self, s0: float, s1: float) -> Features:
        return self._features

    def _local_z(self, x: np.ndarray, s) -> np.ndarray:
        """Local z of points (the only coordinate planes need): one row of the inverse matrix."""
        inv = self._inverse(s)
        if inv.ndim == 2:
            return _affine_row(x, inv[2])
        return np.einsum("nj,nj->n", inv[:, 2, :3], x) + inv[:, 2, 3]

    def _segment_candidates(self, start, end, s_start, s_end) -> np.ndarray | None:
        """Indices of segments that may hit the collider: a plane-like one's by a cheap z test,
        a still sphere's or box's those whose box meets its world box; None when every segment
        must be tested (a moving sphere or box)."""
        shape = self.frame.shape
        if shape not in ("HALF_SPACE", "PLANE"):
            return self._within(0.0, start, end)
        z1 = self._local_z(end, s_end)
        level = self.extent[2]
        if shape == "HALF_SPACE":
            return np.nonzero(z1 < level)[0]
        z0 = self._local_z(start, s_start)
        return np.nonzero((z0 > level) & (z1 <= level) | (z0 < -level) & (z1 >= -level))[0]


def _affine_row(x: np.ndarray, row: np.ndarray) -> np.ndarray:
    """One local coordinate of world points x (n, 3): row (4,) of an inverse affine matrix.
    A row along one axis (a ground or plane that is not turned) reads one column; others take
    one single-threaded pass (a BLAS product would keep a second core spinning, which the
    bake's writer thread needs)."""
    axes = np.nonzero(row[:3])[0]
    if len(axes) == 1:
        k = int(axes[0])
        return x[:, k] * row[k] + row[3]
    return np.einsum("ij,j->i", x, row[:3]) + row[3]


def _affine_range(x: np.ndarray, row: np.ndarray, k: int, both: bool) -> tuple[float, float]:
    """The least and (with ``both``) the largest of ``_affine_row(x, row)`` (else -inf); for a
    row along the one axis ``k`` (else -1), from that column's extremes (a monotone map: the
    same values). NaN where x has one."""
    if k < 0:
        z = _affine_row(x, row)
        return float(np.minimum.reduce(z)), (float(np.maximum.reduce(z)) if both else -np.inf)
    r, c = row[k], x[:, k]
    least, most = (np.minimum, np.maximum) if r > 0.0 else (np.maximum, np.minimum)
    return (float(least.reduce(c) * r + row[3]),
            float(most.reduce(c) * r + row[3]) if both else -np.inf)
