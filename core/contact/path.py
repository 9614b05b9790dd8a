"""What every collider kind answers during one frame interval, and the motion they share.

A collider is a shape in its object's local space moved by an interpolated world transform
(:class:`~physanim.core.transforms.TransformPath`). A point path over a sub-step, x0 (at s0) ->
x1 (at s1), is mapped into the collider's frame at its own times, l0 = M(s0)^-1 x0 and
l1 = M(s1)^-1 x1, which makes a moving collider a static one with the relative motion.

Each kind (analytic shapes in :mod:`.analytic`, triangle meshes in :mod:`.mesh`, listed in
:data:`physanim.core.contact.kinds.KINDS`) subclasses :class:`ColliderPath` and answers the three
questions of the collision passes (:mod:`.response`):

* :meth:`ColliderPath.first_hits`: where segments start -> end first enter the collider;
* :meth:`ColliderPath.push_out`: which points ended inside it, and the surface to put them on;
* :meth:`ColliderPath.near_surface`: which points are near its surface (resting contact).

and one for systems with faces and edges (:mod:`.features`): :meth:`ColliderPath.features`,
the corners, creased edges and round parts that could reach between a mesh's vertices.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..transforms import (TransformPath, divide_rows, inverse3, inverse_affine, norm_rows,
                          row_indices, take, transform_points, transform_vectors)
from .frame import ColliderFrame

SKIN = 1e-4  # [m] particles are placed this far outside a surface after a hit
CONTACT_DISTANCE = 1e-3  # [m] closer than this (and not separating) counts as resting contact
_CORNERS = np.array([(x, y, z) for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])


def same_times(s: float, n: int) -> np.ndarray:
    """(n,) read-only: the time ``s`` of n points, one value broadcast (a collider's path sees
    one matrix for them without comparing n values)."""
    return np.broadcast_to(np.float64(s), (n,))


def padded_box(centre: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The world box (lo, hi) of ``centre`` +- ``half`` (3,), padded against rounding."""
    pad = 1e-9 * (np.abs(centre) + half) + 1e-12
    return centre - half - pad, centre + half + pad


def farthest(*arrays: np.ndarray) -> float:
    """The largest absolute coordinate of the points of ``arrays`` (0 for none; inf where one
    is not finite)."""
    far = 0.0
    for a in arrays:
        if len(a):
            top = max(float(a.max()), -float(a.min()))  # (NaN where a has one)
            if not top <= far:
                far = top if top > far else np.inf  # (NaN: inf, which every caller refuses)
    return far


def uniform_time(s: np.ndarray) -> float | None:
    """The one time of the points' times ``s`` (n,) where they are all one (known without a
    look at the values where it is one value broadcast: :func:`same_times`), else None."""
    if not len(s) or not (s.strides == (0,) or s.min() == s.max()):
        return None
    return float(s[0])


def reach(start: np.ndarray, end: np.ndarray) -> float:
    """A bound on the length of every segment start -> end ((n, 3) each): the length of the
    vector of the columns' largest absolute differences (inf where a value is not finite)."""
    if not len(start):
        return 0.0
    total = 0.0
    for k in range(3):
        d = end[:, k] - start[:, k]
        total += max(float(d.max()), -float(d.min())) ** 2  # (NaN where d has one)
    return float(np.sqrt(total)) if total < np.inf else np.inf


def cut_rows(colliders: list, distance: float, *points: np.ndarray, s=None,
             times: tuple | None = None) -> list | None:
    """For each of ``colliders``, the rows of ``points`` (one or more (n, 3) arrays: each
    row's points, e.g. a segment's two ends) whose box meets its world cut
    (:meth:`ColliderPath.world_cut` for ``distance``; at one time ``s`` for points asked at
    that time; for segments from ``times`` (s_start, s_end: (n,) each, their two ends'
    times) over the time between them where each is one value, else over the interval),
    all worked out together: the rows' boxes
    and their farthest coordinate once, then each collider's few comparisons. None for a
    collider without a cut (or met by every row: all its rows are asked), and None for all when
    fewer than two have one or a point is not finite (each collider then cuts its own). The
    same rows as each collider's own cut (:func:`rows_meeting` on its box): asked for just
    those, it answers as it would for all."""
    if len(colliders) < 2 or not len(points[0]):
        return None
    far = farthest(*points)
    if not far < np.inf:
        return None
    sweep = None  # (s_start, s_end, reach) for moving colliders' cuts of segments
    if times is not None and len(points) == 2 and not all(c.path.static for c in colliders):
        s0, s1 = (uniform_time(t) for t in times)
        if s0 is not None and s1 is not None:
            sweep = (s0, s1, reach(*points))
    cuts = [col.world_cut(distance, far, s, sweep) for col in colliders]
    if sum(cut is not None for cut in cuts) < 2:
        return None
    bounds = []
    for k in range(3):  # each row's least and most coordinate, contiguous
        columns = [a[:, k] for a in points]
        least = np.minimum(columns[0], columns[1]) if len(columns) > 1 else \
            np.ascontiguousarray(columns[0])
        most = np.maximum(columns[0], columns[1]) if len(columns) > 1 else least
        for c in columns[2:]:
            np.minimum(least, c, out=least)
            np.maximum(most, c, out=most)
        bounds.append((least, most))
    out: list = [None] * len(colliders)
    meets = np.empty(len(points[0]), bool)
    here = np.empty_like(meets)
    for i, cut in enumerate(cuts):
        if cut is None:
            continue
        lo, hi = cut
        for k, (least, most) in enumerate(bounds):
            if k:
                np.greater_equal(most, lo[k], out=here)
                meets &= here
            else:
                np.greater_equal(most, lo[k], out=meets)
            np.less_equal(least, hi[k], out=here)
            meets &= here
        rows = np.nonzero(meets)[0]
        out[i] = None if len(rows) == len(meets) else rows
    return out


def times_of(s: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The times ``s`` (n,) of the points ``rows``: one broadcast value stays one
    (:func:`same_times`)."""
    if s.strides == (0,) and len(s):
        return same_times(float(s[0]), len(rows))
    return take(s, rows)


def rows_meeting(lo: np.ndarray, hi: np.ndarray, *points: np.ndarray) -> np.ndarray | None:
    """Indices of the rows whose box over ``points`` (one or more (n, 3) arrays: each row's
    points, e.g. a segment's two ends) meets the world box [lo, hi], or None when every row
    does; column by column. A collider's cheap first cut: points outside its box need no test
    of its shape."""
    meets = None
    for k in range(3):
        columns = [a[:, k] for a in points]
        least = most = columns[0]
        for c in columns[1:]:
            least, most = np.minimum(least, c), np.maximum(most, c)
        here = (most >= lo[k]) & (least <= hi[k])
        meets = here if meets is None else np.logical_and(meets, here, out=meets)
    rows = np.nonzero(meets)[0]
    return None if len(rows) == len(meets) else rows


@dataclass(frozen=True)
class Hits:
    """First hits of the segments that hit (k of them), in the collider's local frame.

    Attributes:
        index: (k,) indices of the segments that hit.
        t: (k,) fraction of each segment before the hit, in [0, 1].
        normal: (k, 3) local unit normals facing the side the segment came from.
        point: (k, 3) local hit points (on the surface proper; :attr:`ColliderPath.offset`
            is added along the normal when a point is placed there).
        element: (k,) int64 surface element hit (a mesh's triangle), or None.
    """

    index: np.ndarray
    t: np.ndarray
    normal: np.ndarray
    point: np.ndarray
    element: np.ndarray | None = None

    @classmethod
    def none(cls) -> Hits:
        return cls(np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))

    def of_rows(self, rows: np.ndarray) -> Hits:
        """These hits of the segments ``rows`` picked out of a larger query, indexed as in it."""
        return replace(self, index=rows[self.index])


@dataclass(frozen=True)
class Features:
    """What of a collider stands out of its surface, in its local frame at a sub-step's start
    (``0``) and end (``1``): corners and round parts as points with a radius (a sphere is its
    centre), creased edges as segments.

    Attributes:
        points0, points1: (k, 3) [local units]. radius: (k,) [local units].
        segments0, segments1: (e, 2, 3) [local units].
    """

    points0: np.ndarray
    points1: np.ndarray
    radius: np.ndarray
    segments0: np.ndarray
    segments1: np.ndarray

    @classmethod
    def none(cls) -> Features:
        return cls.still(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 2, 3)))

    @classmethod
    def still(cls, points: np.ndarray, radius: np.ndarray, segments: np.ndarray) -> Features:
        """Features that do not move in the local frame."""
        return cls(points, points, radius, segments, segments)

    def __len__(self) -> int:
        return len(self.points0) + len(self.segments0)


@dataclass(frozen=True)
class SurfacePoints:
    """Surface points near k query points, in world space.

    Attributes:
        index: (k,) indices of the query points.
        point: (k, 3) surface points [m] (on the surface proper, see :attr:`Hits.point`).
        normal: (k, 3) unit normals facing the query points' side.
        velocity: (k, 3) the surface's velocity there [m/s].
        gap: (k,) distance of each query point beyond the surface, ``offset`` included [m]
            (negative: inside).
        axis: ``(a, sign)`` when every normal is ``sign`` times the world axis ``a`` and every
            velocity is zero (a still ground that is not turned: the common case, which
            :class:`~.contacts.ContactForce` takes by columns); None: any normals.
    """

    index: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    velocity: np.ndarray
    gap: np.ndarray
    axis: tuple[int, float] | None = None

    @classmethod
    def none(cls) -> SurfacePoints:
        return cls(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)),
                   np.zeros(0))

    def of_rows(self, rows: np.ndarray) -> SurfacePoints:
        """These points of the query points ``rows`` picked out of a larger query, indexed as
        in it."""
        return replace(self, index=rows[self.index])

    def take(self, rows: np.ndarray) -> SurfacePoints:
        """These points' rows ``rows`` (indices or a mask)."""
        rows = row_indices(rows)
        return SurfacePoints(*(take(getattr(self, k), rows) for k in _SURFACE_ROWS), self.axis)

    @classmethod
    def joined(cls, parts: list[SurfacePoints]) -> SurfacePoints:
        """The rows of ``parts`` one after another."""
        if len(parts) == 1:
            return parts[0]
        axes = {p.axis for p in parts}
        return cls(*(np.concatenate([getattr(p, k) for p in parts]) for k in _SURFACE_ROWS),
                   axes.pop() if len(axes) == 1 else None)


_SURFACE_ROWS = ("index", "point", "normal", "velocity", "gap")  # SurfacePoints' row arrays


class ColliderPath:
    """One collider during one frame interval, with its motion path.

    Subclasses implement :meth:`first_hits`, :meth:`push_out` and :meth:`near_surface`.

    Attributes:
        frame: the collider's settings for this interval.
        path: its world transform over the interval (s = 0..1).
        frame_dt: the interval's length [s].
        per_metre: (3,) local units per world metre along each local axis.
        offset: [m] world distance kept between a placed point and the surface proper, beyond
            :data:`SKIN` (0 for analytic shapes, whose extent already includes the thickness).
    """

    offset: float = 0.0
    hits_end_surface: bool = False  # hit points lie on the surface at the sub-step's END
    deforming: bool = False  # its surface moves in its own frame (a mesh's vertices)
    # a path that is a function of its frame alone (no state, nothing kept for the run): the
    # next interval of a collider standing still can use the same one
    reusable: bool = False

    def __init__(self, frame: ColliderFrame, frame_dt: float):
        self.frame = frame
        self.frame_dt = frame_dt
        self.path = TransformPath(frame.matrix0, frame.matrix1, frame.matrices)
        self._inverse0 = inverse_affine(self.path.m0)
        # a collider that stands still: its inverse and inverse-transpose, once per frame
        self._normals0 = np.swapaxes(self._inverse0[:3, :3], -1, -2)
        self.per_metre = np.linalg.norm(self._inverse0[:3, :3], axis=1)

    @property
    def still(self) -> bool:
        """Whether the collider neither moves nor deforms over its interval."""
        return self.path.static and not self.deforming

    @classmethod
    def build(cls, frame: ColliderFrame, frame_dt: float, owner) -> ColliderPath:
        """The path of ``frame``; ``owner`` (a :class:`~.kinds.ColliderPaths`) keeps what lasts
        between frame intervals, for the kinds that keep anything."""
        return cls(frame, frame_dt)

    # -- motion ---------------------------------------------------------------------------------
    def _at(self, s) -> np.ndarray:
        """The matrix at ``s``: one (4, 4) when s is a scalar or the same for every particle
        (the common case, far cheaper; known without a look at its values where ``s`` is one
        value broadcast, as :func:`same_times` makes), else (n, 4, 4)."""
        s = np.asarray(s, dtype=np.float64)
        if self.path.static:
            return self.path.m0
        one = float(s) if s.ndim == 0 else uniform_time(s)
        if one is not None:
            return self._once(one)[0]
        return self.path.matrices(s)

    def _once(self, s: float) -> tuple:
        """The matrix at one ``s`` and its inverse (read-only), worked out once per interval:
        a sub-step asks for each of its times several times."""
        known = self.__dict__.setdefault("_known_at", {})  # (paths saved before it: none)
        at = known.get(s)
        if at is None:
            m = self.path.matrices(s)
            at = known[s] = (m, inverse_affine(m))
            for a in at:
                a.flags.writeable = False
        return at

    def _inverse(self, s) -> np.ndarray:
        """The inverse of :meth:`_at` (of a collider standing still: worked out once)."""
        if self.path.static:
            return self._inverse0
        m = self._at(s)
        return self._once(float(np.asarray(s).flat[0]))[1] if m.ndim == 2 else inverse_affine(m)

    def to_local(self, x: np.ndarray, s) -> np.ndarray:
        return transform_points(self._inverse(s), x)

    def to_world(self, l: np.ndarray, n_local: np.ndarray, s):
        """World points and unit normals of local points/normals at parameters s."""
        m = self._at(s)
        p = transform_points(m, l)
        normals = (self._normals0 if self.path.static  # the inverse-transpose
                   else np.swapaxes(inverse3(m[..., :3, :3]), -1, -2))
        n = transform_vectors(normals, n_local)
        divide_rows(n, norm_rows(n), out=n)
        return p, n

    def surface_velocity(self, l: np.ndarray, s, element: np.ndarray | None = None) -> np.ndarray:
        """World velocity [m/s] of the surface at local points ``l`` (on ``element``) at s."""
        if self.path.static:
            return np.zeros_like(l)
        return self.path.point_velocities(l, np.broadcast_to(np.asarray(s, float), len(l)),
                                          self.frame_dt)

    # -- the three questions --------------------------------------------------------------------
    def first_hits(self, start: np.ndarray, end: np.ndarray, s_start: np.ndarray,
                   s_end: np.ndarray) -> Hits:
        """First entry of world segments start (at s_start) -> end (at s_end), (n, 3) and (n,),
        into the collider; a collider that moved onto an end point counts as a hit at t = 1."""
        raise NotImplementedError

    def push_out(self, x: np.ndarray, s: np.ndarray, start: np.ndarray,
                 s_start: np.ndarray) -> SurfacePoints:
        """Points x (n, 3) at s (n,) found inside the collider (or, for a surface without an
        inside, past it since ``start`` at ``s_start``), with the surface to put them on."""
        raise NotImplementedError

    def near_surface(self, x: np.ndarray, s: float) -> SurfacePoints:
        """Points x (n, 3) whose ``gap`` to the surface at s is below CONTACT_DISTANCE."""
        raise NotImplementedError

    def world_cut(self, distance: float, far: float, s=None, sweep: tuple | None = None
                  ) -> tuple | None:
        """A world box (lo, hi) (3,) outside which no point (whose coordinates are at most
        ``far`` in size) lies within ``distance`` [m] of the collider, enters it or is inside
        it at any time of the interval (with ``s``: at that time; with ``sweep`` (s_start,
        s_end, reach): no segment from s_start to s_end of at most ``reach`` [m] enters it
        or ends inside it): what its own first cut keeps (:func:`cut_rows` asks every
        collider's at once); None where it has none."""
        return None

    # -- segments over one time span: where a moving collider can meet them ---------------------
    def _swept_box(self, s0: float, s1: float, centre: np.ndarray, half: np.ndarray,
                   length: float) -> tuple | None:
        """A world box that every segment from time ``s0`` to ``s1``, at most ``length`` [m]
        long, meets if a point of its local segment (l0 -> l1, each end mapped at its own
        time, as the kinds test them) lies in the local box ``centre`` +- ``half`` (3,) (the
        shape, padded by what its tests may round to): that box's world box at s0 grown by
        how far the collider's motion relative to the segment can carry the meeting point.

        Measure local points in metres but unturned: y = S l, with A0 = R S the matrix at s0
        split into a rotation (or reflection) R and a stretch S. At s0, y = R^T (x - c0)
        (c0 the local origin then), a rigid map of the world point x; at s1, y = Q y0 + q
        with Q = S B1 R and q = S (B1 c0 + d1) (B1, d1 the inverse at s1): the identity and
        nothing for a collider standing still, a turn and a move for a rigid body. A meeting
        point y = (1 - t) y0(x0) + t y1(x1) lies in the box (|y| <= r, its farthest corner
        from the origin), and y0(x) at the segment's point x = (1 - t) x0 + t x1 differs
        from it by t ((Q - I) y0(x1) + q), at most w = (b (r + length) + |q|) / (1 - b) with
        b = |Q - I| (as |y0(x1)| <= |y0(x)| + length <= r + w + length). So x lies within
        A0's image of the box, grown by w along every world axis. None where b is not small
        (a turn or change of scale too fast for a bound) or a matrix is not one (``s0`` and
        ``s1`` are single times: :meth:`sweep_rows` and :func:`cut_rows` ask only then)."""
        m0, inv1 = self._at(s0), self._inverse(s1)
        if m0.ndim != 2 or inv1.ndim != 2:
            return None
        b, q = self._motion(s0, s1)
        if not b < 0.5:
            return None
        a0 = m0[:3, :3]
        r = float(norm_rows((centre + half * _CORNERS) @ a0.T).max())
        w = (b * (r + length) + q) / (1.0 - b)
        return padded_box(a0 @ centre + m0[:3, 3], (np.abs(a0) @ half + w) * (1.0 + 1e-9))

    def _motion(self, s0: float, s1: float) -> tuple[float, float]:
        """b and |q| of the motion from s0 to s1 (:meth:`_swept_box`), worked out once per
        pair of times."""
        known = self.__dict__.setdefault("_swept", {})  # (paths saved before it: none)
        motion = known.get((s0, s1))
        if motion is None:
            m0, inv1 = self._at(s0), self._inverse(s1)
            a0, c0 = m0[:3, :3], m0[:3, 3]
            u, stretch, vt = np.linalg.svd(a0)
            turn, unturned = u @ vt, (vt.T * stretch) @ vt
            b = float(np.linalg.norm(unturned @ inv1[:3, :3] @ turn - np.eye(3), 2))
            q = float(np.linalg.norm(unturned @ (inv1[:3, :3] @ c0 + inv1[:3, 3])))
            motion = known[(s0, s1)] = (b, q)
        return motion

    def _local_far(self, far: float, s0: float, s1: float) -> float:
        """The largest local coordinate, at s0 or s1, of a point up to ``far`` along every
        world axis (what the maps and the tests may round by)."""
        return max(float(np.abs(inv[:3, :3]).sum(axis=1).max()) * far +
                   float(np.abs(inv[:3, 3]).max())
                   for inv in (self._inverse(s0), self._inverse(s1)))

    def sweep_rows(self, start: np.ndarray, end: np.ndarray, s_start: np.ndarray,
                   s_end: np.ndarray) -> np.ndarray | None:
        """A moving collider's cut of segments start -> end, each from the one time s_start
        to the one time s_end: the rows whose box meets its world cut over that span
        (:meth:`world_cut` with a sweep); None where the times differ, every row meets it,
        or it bounds nothing."""
        s0, s1 = uniform_time(s_start), uniform_time(s_end)
        if s0 is None or s1 is None:
            return None
        far = farthest(start, end)
        box = self.world_cut(0.0, far, None, (s0, s1, reach(start, end))) \
            if far < np.inf else None
        return None if box is None else rows_meeting(*box, start, end)

    def apart(self, points: tuple, s: float, distance: float) -> bool:
        """Whether every point of the (n, 3) arrays ``points``, and every segment between
        two of them, lies farther than ``distance`` [m] outside the collider at ``s``: then
        none is near its surface, enters it or is inside it, and the questions above answer
        nothing for them. One bound over all the points instead of a test of each; False
        where no such bound is known (the questions then answer as always)."""
        return False

    def features(self, s0: float, s1: float) -> Features:
        """The collider's corners, creased edges and round parts at s0 and s1 (none: a
        surface without any, like the infinite ground, which no face can meet before one of
        its vertices does)."""
        return Features.none()
