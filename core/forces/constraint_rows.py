"""Hard constraints on a point set, each kind as rows of Witkin & Baraff's "constrained
dynamics": a scalar C(x, t) = 0 per row, its gradient J (which touches one or two points), its
rate C' = J v + dC/dt and the J' v term of C'' = J a + J' v (+ d2C/dt2, zero here: anchors and
targets move at constant velocity within one sub-step).

Every kind is vectorised over its constraints and returns :class:`Rows`; a set of kinds is
joined by :func:`gather`. Units: positions [m], velocities [m/s], C [m].
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..transforms import cross, dot_rows, norm_rows, tangents

NO_POINT = -1  # a row's second point when it touches only one


@dataclass
class Rows:
    """m constraint rows at one state.

    Attributes:
        point: (m, 2) int, the points each row touches (``NO_POINT`` for none).
        jac: (m, 2, 3) dC/dx of each touched point.
        c: (m,) C [m]. cdot: (m,) C' [m/s]. jdot_v: (m,) J' v [m/s^2].
    """

    point: np.ndarray
    jac: np.ndarray
    c: np.ndarray
    cdot: np.ndarray
    jdot_v: np.ndarray

    @property
    def count(self) -> int:
        return len(self.c)

    @classmethod
    def empty(cls) -> Rows:
        return cls(np.zeros((0, 2), np.int64), np.zeros((0, 2, 3)), np.zeros(0), np.zeros(0),
                   np.zeros(0))


def gather(parts: list[Rows]) -> Rows:
    """The rows of several kinds as one set."""
    parts = [p for p in parts if p.count]
    if not parts:
        return Rows.empty()
    if len(parts) == 1:
        return parts[0]
    return Rows(*(np.concatenate([getattr(p, k) for p in parts])
                  for k in ("point", "jac", "c", "cdot", "jdot_v")))


def _as_points(a, count: int, name: str) -> np.ndarray:
    a = np.broadcast_to(np.asarray(a, dtype=np.float64), (count, 3))
    if not np.all(np.isfinite(a)):
        raise ValueError(f"constraint {name} must be finite")
    return a


def _per_point(kind, **vectors: str) -> int:
    """Freeze a kind's point indices ``i`` (r,) and its per-point vectors (r, 3) (given by
    field name -> what messages call it); returns r."""
    i = np.atleast_1d(np.asarray(kind.i, np.int64))
    object.__setattr__(kind, "i", i)
    for key, label in vectors.items():
        object.__setattr__(kind, key, _as_points(getattr(kind, key), len(i), label))
    return len(i)


def _as_lengths(a, count: int, name: str) -> np.ndarray:
    a = np.broadcast_to(np.asarray(a, dtype=np.float64), (count,))
    if not np.all(np.isfinite(a)) or np.any(a < 0.0):
        raise ValueError(f"constraint {name} must be finite and >= 0 (got {a.min()})")
    return a


def _distance_rows(d: np.ndarray, vr: np.ndarray, length: np.ndarray):
    """C = |d| - L for separation d (r, 3) changing at vr: (unit u, C, C', J' v)."""
    norm = np.sqrt(dot_rows(d, d))
    safe = np.where(norm > 1e-12, norm, 1.0)
    u = d / safe[:, None]
    u[norm <= 1e-12] = (0.0, 0.0, 1.0)  # coincident ends: any direction; C' and C'' stay exact
    along = dot_rows(u, vr)
    return u, norm - length, along, (dot_rows(vr, vr) - along * along) / safe


@dataclass(frozen=True)
class Rods:
    """Rigid rods between point pairs: |x_a - x_b| = length (a particle rope's links).

    Args: a, b: (r,) point indices. length: (r,) or one value [m].
    """

    a: np.ndarray
    b: np.ndarray
    length: np.ndarray

    def __post_init__(self):
        a, b = np.asarray(self.a, np.int64), np.asarray(self.b, np.int64)
        if a.shape != b.shape or a.ndim != 1:
            raise ValueError(f"rod ends must be two equal 1-D index arrays (got {a.shape}, "
                             f"{b.shape})")
        if np.any(a == b):
            raise ValueError(f"a rod joins point {int(a[a == b][0])} to itself")
        object.__setattr__(self, "a", a)
        object.__setattr__(self, "b", b)
        object.__setattr__(self, "length", _as_lengths(self.length, len(a), "rod length"))

    def rows(self, x: np.ndarray, v: np.ndarray, t: float) -> Rows:
        u, c, cdot, jdv = _distance_rows(x[self.a] - x[self.b], v[self.a] - v[self.b],
                                         self.length)
        return Rows(np.stack([self.a, self.b], axis=1), np.stack([u, -u], axis=1), c, cdot, jdv)


@dataclass(frozen=True)
class Tethers:
    """Rods from points to anchors moving at constant velocity (a pendulum's pivot, a point
    on a sphere's surface): |x_i - p(t)| = length, p(t) = anchor + (t - t0) anchor_v.

    Args: i: (r,) point indices. anchor, anchor_v: (r, 3) or (3,) at t0 [m], [m/s].
    length: (r,) or one value [m]. t0: time of ``anchor`` [s].
    """

    i: np.ndarray
    anchor: np.ndarray
    length: np.ndarray
    anchor_v: np.ndarray = (0.0, 0.0, 0.0)
    t0: float = 0.0

    def __post_init__(self):
        count = _per_point(self, anchor="anchor", anchor_v="anchor velocity")
        object.__setattr__(self, "length", _as_lengths(self.length, count, "tether length"))

    def rows(self, x: np.ndarray, v: np.ndarray, t: float) -> Rows:
        p = self.anchor + (t - self.t0) * self.anchor_v
        u, c, cdot, jdv = _distance_rows(x[self.i] - p, v[self.i] - self.anchor_v, self.length)
        return Rows(_single(self.i), _first(u), c, cdot, jdv)


@dataclass(frozen=True)
class OnPlanes:
    """Points kept on planes through ``origin`` (moving at constant velocity) with unit
    ``normal``: n . (x - o(t)) = 0, o(t) = origin + (t - t0) origin_v.

    Args: i: (r,) point indices. origin, normal: (r, 3) or (3,). origin_v: [m/s]. t0 [s].
    """

    i: np.ndarray
    origin: np.ndarray
    normal: np.ndarray
    origin_v: np.ndarray = (0.0, 0.0, 0.0)
    t0: float = 0.0

    def __post_init__(self):
        _per_point(self, origin="plane origin", normal="plane normal",
                   origin_v="plane velocity")
        norm = np.sqrt(dot_rows(self.normal, self.normal))
        if np.any(norm < 1e-12):
            raise ValueError("constraint plane normal must not be zero")
        object.__setattr__(self, "normal", self.normal / norm[:, None])

    def rows(self, x: np.ndarray, v: np.ndarray, t: float) -> Rows:
        n = self.normal
        o = self.origin + (t - self.t0) * self.origin_v
        return Rows(_single(self.i), _first(n), dot_rows(n, x[self.i] - o),
                    dot_rows(n, v[self.i] - self.origin_v), np.zeros(len(self.i)))


def on_spheres(i, centre, radius) -> Tethers:
    """Points kept on sphere surfaces: |x - centre| = radius."""
    return Tethers(i, centre, radius)


def on_circles(i, centre, axis, radius, centre_v=(0.0, 0.0, 0.0), t0: float = 0.0) -> list:
    """Beads on circular wires (centre moving at ``centre_v``, unit axis, radius): the sphere of
    the wire's radius and the plane of the wire, two rows per bead — Witkin's bead on a
    wire."""
    return [OnPlanes(i, centre, axis, centre_v, t0), Tethers(i, centre, radius, centre_v, t0)]


CURVE_BLOCK = 16  # a wire's segments per bounding sphere of the nearest search
CURVE_CHUNK = 1 << 18  # bead-to-sphere distances per pass (memory bound of that search)


@dataclass(frozen=True)
class OnCurves:
    """Beads on a wire of any shape: the polyline through ``points`` (closed when ``cyclic``),
    each vertex moving at constant velocity, points(t) = points + (t - t0) points_v.

    Each bead is held on the polyline by two rows, n_k . (x - p) = 0 for the nearest point p
    and two unit normals n_1, n_2 across the wire there. The wire is taken as the smooth curve
    the polyline samples: its unit tangent T and curvature vector K (from the circle through
    each vertex and its two neighbours, exact for a sampled circle) are interpolated along each
    segment, the normals are taken across T, and J' v = -(n_k . K) (T . v_rel)^2 is the pull
    that turns a bead running along the wire (as a circle's sphere row gives it). A bead then
    turns smoothly from segment to segment instead of losing speed at every vertex; the
    projection after each step keeps it on the polyline itself. Past an open wire's ends, it
    runs on along the end segments' lines.

    Args: i: (r,) point indices. points: (P, 3) the wire's vertices at t0 [m], P >= 2.
    points_v: (P, 3) or (3,) their velocities [m/s]. cyclic: the last vertex joins the first.
    t0 [s].
    """

    i: np.ndarray
    points: np.ndarray
    points_v: np.ndarray = (0.0, 0.0, 0.0)
    cyclic: bool = False
    t0: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "i", np.atleast_1d(np.asarray(self.i, np.int64)))
        pts = np.asarray(self.points, np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 2:
            raise ValueError(f"a wire needs at least two points (got an array of shape "
                             f"{pts.shape})")
        object.__setattr__(self, "points", _as_points(pts, len(pts), "wire point"))
        object.__setattr__(self, "points_v", _as_points(self.points_v, len(pts),
                                                        "wire point velocity"))
        tangent, _ = _wire_frames(self.points, self.cyclic)
        object.__setattr__(self, "_across", _transported(self.points, tangent, self.cyclic))

    def rows(self, x: np.ndarray, v: np.ndarray, t: float) -> Rows:
        pts = self.points + (t - self.t0) * self.points_v
        start = np.arange(len(pts) if self.cyclic else len(pts) - 1)
        end = (start + 1) % len(pts)
        tangent, curvature = _wire_frames(pts, self.cyclic)
        seg, u = _nearest_on_segments(x[self.i], pts[start], pts[end])
        a, b = start[seg], end[seg]
        w = u[:, None]
        p = (1.0 - w) * pts[a] + w * pts[b]
        rel = v[self.i] - ((1.0 - w) * self.points_v[a] + w * self.points_v[b])
        along = (1.0 - w) * tangent[a] + w * tangent[b]
        along /= np.maximum(norm_rows(along), 1e-300)[:, None]  # (ends: the segment's own)
        bend = (1.0 - w) * curvature[a] + w * curvature[b]
        bend -= dot_rows(bend, along)[:, None] * along
        # the normals follow the wire without turning about it (the same at a step's start and
        # end, which RATTLE's projection pairs): a normal carried along the wire, made
        # square to the tangent here
        n1 = (1.0 - w) * self._across[a] + w * self._across[b]
        n1 -= dot_rows(n1, along)[:, None] * along
        n1 /= norm_rows(n1)[:, None]
        n2 = cross(along, n1)
        normals = np.stack([n1, n2], axis=1).reshape(-1, 3)  # a bead's two rows side by side
        bead = np.repeat(np.arange(len(self.i)), 2)
        speed = dot_rows(along, rel)[bead]
        return Rows(_single(self.i[bead]), _first(normals),
                    dot_rows(normals, x[self.i][bead] - p[bead]), dot_rows(normals, rel[bead]),
                    -dot_rows(normals, bend[bead]) * speed * speed)


def _wire_frames(pts: np.ndarray, cyclic: bool) -> tuple[np.ndarray, np.ndarray]:
    """(P, 3) unit tangents and curvature vectors [1/m] at a polyline's vertices: the tangent
    halves the turn between a vertex's two segments, the curvature is that of the circle
    through the vertex and its neighbours (zero at an open polyline's ends and where segments
    have no length)."""
    nxt = np.roll(pts, -1, axis=0) - pts  # segment k: vertex k -> k + 1
    length = norm_rows(nxt)
    unit = nxt / np.where(length > 0.0, length, 1.0)[:, None]
    before, after = np.roll(unit, 1, axis=0), unit  # the segments into and out of each vertex
    length_in = np.roll(length, 1)
    if not cyclic:
        before[0], after[-1] = after[0], before[-1]
        length_in[0] = length[-1] = 0.0
    tangent = before + after
    norm = norm_rows(tangent)
    tangent = np.where((norm > 1e-12)[:, None], tangent / np.where(norm > 1e-12, norm, 1.0)[:, None],
                       after)
    chord = norm_rows(before * length_in[:, None] + after * length[:, None])
    turn = after - before  # points into the bend, |turn| = 2 sin(angle / 2)
    sine = norm_rows(cross(before, after))
    ok = (length_in > 0.0) & (length > 0.0) & (chord > 0.0)
    kappa = np.where(ok, 2.0 * sine / np.where(ok, chord, 1.0), 0.0)
    t_norm = norm_rows(turn)
    curvature = turn / np.where(t_norm > 0.0, t_norm, 1.0)[:, None] * kappa[:, None]
    return tangent, curvature


def _transported(pts: np.ndarray, tangent: np.ndarray, cyclic: bool) -> np.ndarray:
    """(P, 3) a unit normal at each vertex carried along the polyline without turning about it
    (a rotation-minimising frame, by projection from vertex to vertex); on a closed wire the
    twist it gathers round the loop is spread evenly along it, so the frame closes."""
    across = np.empty_like(tangent)
    across[0] = tangents(tangent[:1])[0][0]
    for k in range(1, len(pts)):
        n = across[k - 1] - (across[k - 1] @ tangent[k]) * tangent[k]
        size = math.sqrt(n @ n)
        across[k] = n / size if size > 1e-9 else tangents(tangent[k:k + 1])[0][0]
    if cyclic:
        back = across[-1] - (across[-1] @ tangent[0]) * tangent[0]  # carried round to vertex 0
        twist = math.atan2(cross(across[0], back) @ tangent[0], across[0] @ back)
        run = np.concatenate([[0.0], np.cumsum(norm_rows(np.diff(pts, axis=0)))])
        total = run[-1] + float(np.linalg.norm(pts[0] - pts[-1]))
        angle = -twist * run / total  # turn each back about its tangent
        side = cross(tangent, across)
        across = np.cos(angle)[:, None] * across + np.sin(angle)[:, None] * side
    return across


def _nearest_on_segments(x: np.ndarray, a: np.ndarray, b: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
    """For points x (r, 3), the nearest of the segments a -> b (s, 3) (the first on ties) and
    the parameter u in [0, 1] of the nearest point on it. The segments are taken in runs of
    CURVE_BLOCK, each bounded by a sphere: only the runs a point could be nearest to (nearer
    than the farthest point of the run nearest it) are searched segment by segment."""
    d = b - a
    dd = dot_rows(d, d)
    safe = np.where(dd > 0.0, dd, 1.0)

    def param(bead, seg):
        return np.clip(dot_rows(x[bead] - a[seg], d[seg]) / safe[seg], 0.0, 1.0)

    blocks = -(-len(a) // CURVE_BLOCK)
    ends = np.stack([a, b], axis=1).reshape(-1, 6)
    pad = np.concatenate([ends, np.repeat(ends[-1:], blocks * CURVE_BLOCK - len(a), axis=0)])
    run = pad.reshape(blocks, 2 * CURVE_BLOCK, 3)
    centre = 0.5 * (run.min(axis=1) + run.max(axis=1))
    radius = np.sqrt(np.max(np.sum((run - centre[:, None]) ** 2, axis=2), axis=1))
    seg = np.zeros(len(x), np.int64)
    step = max(1, CURVE_CHUNK // max(blocks, 1))
    for lo in range(0, len(x), step):
        far = norm_rows((x[lo:lo + step, None, :] - centre[None]).reshape(-1, 3)).reshape(
            -1, blocks)
        near = far - radius <= np.min(far + radius, axis=1, keepdims=True)
        bead, block = np.nonzero(near)  # by bead, then block: each bead's segments in order
        bead = np.repeat(bead, CURVE_BLOCK)
        cand = (np.repeat(block * CURVE_BLOCK, CURVE_BLOCK)
                + np.tile(np.arange(CURVE_BLOCK), len(block)))
        real = cand < len(a)
        bead, cand = bead[real] + lo, cand[real]
        off = x[bead] - a[cand] - param(bead, cand)[:, None] * d[cand]
        order = np.lexsort((cand, dot_rows(off, off), bead))
        first = np.ones(len(order), bool)
        first[1:] = bead[order][1:] != bead[order][:-1]
        seg[bead[order][first]] = cand[order][first]
    return seg, param(np.arange(len(x)), seg)


@dataclass(frozen=True)
class Pins:
    """Points held on targets moving at constant velocity: x_i = p(t), three rows each.

    Args: i: (r,) point indices. target, target_v: (r, 3) at t0 [m], [m/s]. t0 [s].
    """

    i: np.ndarray
    target: np.ndarray
    target_v: np.ndarray = (0.0, 0.0, 0.0)
    t0: float = 0.0

    def __post_init__(self):
        _per_point(self, target="pin target", target_v="pin velocity")

    def rows(self, x: np.ndarray, v: np.ndarray, t: float) -> Rows:
        r = len(self.i)
        p = self.target + (t - self.t0) * self.target_v
        axes = np.broadcast_to(np.eye(3), (r, 3, 3))  # row k of pin j: dC/dx = e_k
        point = np.repeat(self.i, 3)
        return Rows(np.stack([point, np.full(3 * r, NO_POINT)], axis=1),
                    _first(axes.reshape(3 * r, 3)), (x[self.i] - p).ravel(),
                    (v[self.i] - self.target_v).ravel(), np.zeros(3 * r))


def _single(i: np.ndarray) -> np.ndarray:
    return np.stack([i, np.full(len(i), NO_POINT)], axis=1)


def _first(j: np.ndarray) -> np.ndarray:
    """(r, 2, 3) Jacobian of rows touching one point: ``j`` on it, zeros for the empty slot."""
    return np.stack([j, np.zeros_like(j)], axis=1)
