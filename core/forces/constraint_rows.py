"""Hard constraints on a point set, each kind as rows of Witkin & Baraff's "constrained
dynamics": a scalar C(x, t) = 0 per row, its gradient J (which touches one or two points), its
rate C' = J v + dC/dt and the J' v term of C'' = J a + J' v (+ d2C/dt2, zero here: anchors and
targets move at constant velocity within one sub-step).

Every kind is vectorised over its constraints and returns :class:`Rows`; a set of kinds is
joined by :func:`gather`. Units: positions [m], velocities [m/s], C [m].
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import dot_rows

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
