"""What every bounding-volume type provides, and batched reductions over groups of points.

A bounding-volume *kind* (:class:`~.sphere.Sphere`, :class:`~.kdop.KDOP` — of which the AABB is
the 6-DOP —, :class:`~.obb.OBB`) is a stateless object whose methods work on packed float arrays:
one row of ``kind.width`` numbers per volume, so a hierarchy stores all its volumes in one
``node_bv`` array and every operation is vectorised over rows. Each kind documents its layout.

Groups. Fits are batched over many groups of points at once: ``starts``/``counts`` select
disjoint, non-empty ranges ``points[starts[i]:starts[i] + counts[i]]`` (a hierarchy's nodes at
one depth), or ``points`` may be (g, n, 3) for g equal-sized groups.

Conservativeness. Fits contain their points up to rounding; overlap, ray and distance tests take
a ``margin`` [m] by which both volumes count as grown. Queries pass a margin of
:data:`PAD_REL` times the coordinates' magnitude, far above any rounding error and far below any
physical size, so a test on volumes never rejects what the exact primitive test would accept.
"""
from __future__ import annotations

import numpy as np

from ..errors import PhysanimError
from ..transforms import inverse_affine

PAD_REL = 1e-9  # margin used by queries, relative to the largest coordinate magnitude


class Groups:
    """Points of g disjoint groups gathered contiguously: group i is
    ``points[offsets[i]:offsets[i + 1]]``.

    Args:
        points: (m, 3) gathered points.
        offsets: (g + 1,) int64 group boundaries.
    """

    def __init__(self, points: np.ndarray, offsets: np.ndarray):
        self.points = points
        self.offsets = offsets
        self.counts = np.diff(offsets)
        self.first = offsets[:-1]

    @property
    def group_count(self) -> int:
        return len(self.counts)

    def reduce(self, ufunc, values: np.ndarray) -> np.ndarray:
        """``ufunc`` reduced over each group of per-point ``values`` (m, ...) -> (g, ...)."""
        return ufunc.reduceat(values, self.first, axis=0)

    def spread(self, per_group: np.ndarray) -> np.ndarray:
        """Per-group values (g, ...) repeated for each point (m, ...)."""
        return np.repeat(per_group, self.counts, axis=0)


def gather(points: np.ndarray, starts=None, counts=None) -> tuple[Groups, bool]:
    """Gather point groups contiguously.

    Args:
        points: (n, 3) points, or (g, n, 3) for g groups of n points.
        starts, counts: (g,) disjoint non-empty ranges of ``points`` (n, 3); both None for one
            group of all points.

    Returns:
        (groups, single): ``single`` is True when the caller asked for one group (no ranges).
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim == 3:
        g, n = p.shape[:2]
        if n == 0:
            raise ValueError("cannot fit a bounding volume to an empty group of points")
        return Groups(p.reshape(-1, 3), np.arange(g + 1, dtype=np.int64) * n), False
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points must be (n, 3) or (g, n, 3) (got shape {p.shape})")
    if starts is None:
        if len(p) == 0:
            raise ValueError("cannot fit a bounding volume to no points")
        return Groups(p, np.array([0, len(p)], dtype=np.int64)), True
    starts = np.asarray(starts, dtype=np.int64)
    counts = np.asarray(counts, dtype=np.int64)
    if np.any(counts <= 0):
        raise ValueError(f"point groups must be non-empty (group {int(np.argmin(counts))} "
                         f"has {int(counts.min())} points)")
    offsets = np.concatenate([[0], np.cumsum(counts)])
    if len(starts) and not (starts[0] == 0 and offsets[-1] == len(p)
                            and np.array_equal(starts, offsets[:-1])):
        idx = np.repeat(starts - offsets[:-1], counts) + np.arange(offsets[-1])
        p = p[idx]
    return Groups(p, offsets), False


def linear_part(matrix) -> tuple[np.ndarray, np.ndarray]:
    """(A (3, 3), t (3,)) of a finite (4, 4) affine matrix."""
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise ValueError(f"a transform must be a finite 4x4 matrix (got {m.shape}: {m.tolist()})")
    return m[:3, :3], m[:3, 3]


def world_frame(matrix, name: str = "transform") -> tuple[np.ndarray, np.ndarray]:
    """(M, M^-1) of an invertible, finite (4, 4) local-to-world matrix."""
    a, _ = linear_part(matrix)
    det = float(np.linalg.det(a))
    if not (np.isfinite(det) and abs(det) > 0.0):
        raise PhysanimError(f"is singular (determinant {det:g}): it flattens the mesh",
                            obj=name, kind="transform")
    m = np.asarray(matrix, dtype=np.float64)
    return m, inverse_affine(m)


def similarity_scale(matrix, name: str = "transform") -> float:
    """Uniform scale s of a similarity transform (rotation or mirror, times s, plus translation).

    Raises:
        PhysanimError: the matrix shears or scales non-uniformly (apply its scale to the mesh's
            vertices first).
    """
    a, _ = linear_part(matrix)
    gram = a.T @ a
    s2 = float(np.trace(gram)) / 3.0
    if s2 <= 0.0 or np.abs(gram - s2 * np.eye(3)).max() > 1e-9 * s2:
        raise PhysanimError(f"must be rigid (rotation, translation, uniform scale); got linear "
                            f"part {np.round(a, 6).tolist()} — apply its scale to the mesh",
                            obj=name, kind="transform")
    return float(np.sqrt(s2))


def box_axes_by_extent(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World axes (g, 3, 3) ordered longest first, and the box centres (g, 3)."""
    order = np.argsort(-(hi - lo), axis=1, kind="stable")
    return np.eye(3)[order], 0.5 * (lo + hi)


class BoundingVolume:
    """Interface of a bounding-volume kind. Arrays hold one volume per row (n, width)."""

    name = "abstract"
    width = 0
    is_box = False  # an axis-aligned box laid out as [lo (3), hi (3)] (segment tests use it)

    def fit(self, points, starts=None, counts=None) -> np.ndarray:
        """Tightest volume of this kind's construction around each group of points.

        Returns (width,) for one group (no ``starts``), else (g, width).
        """
        groups, single = gather(points, starts, counts)
        bv = self.fit_groups(groups)
        return bv[0] if single else bv

    def fit_groups(self, groups: Groups) -> np.ndarray:
        raise NotImplementedError

    def fit_triangles(self, tri: np.ndarray, starts, counts) -> np.ndarray:
        """Volumes (g, width) around groups of triangles (n, 3, 3) given as triangle ranges."""
        return self.fit(tri.reshape(-1, 3), 3 * np.asarray(starts), 3 * np.asarray(counts))

    def refit_triangles(self, bv: np.ndarray, tri: np.ndarray, starts, counts) -> np.ndarray:
        """New volumes around moved triangles; kinds may keep parts of the old ``bv`` (g, width)."""
        return self.fit_triangles(tri, starts, counts)

    def overlap(self, a: np.ndarray, b: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """(n,) bool: volumes a[i] and b[i] (same frame) come within ``margin`` [m]."""
        raise NotImplementedError

    def transform(self, bv: np.ndarray, matrix) -> np.ndarray:
        """Volumes (n, width) enclosing the given ones mapped by a 4x4 affine ``matrix``."""
        raise NotImplementedError

    def merge(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(n, width) volumes enclosing both a[i] and b[i]."""
        raise NotImplementedError

    def volume(self, bv: np.ndarray) -> np.ndarray:
        """(n,) enclosed volume [m^3]."""
        return self.measure(bv, 0.0)

    def measure(self, bv: np.ndarray, pad: float) -> np.ndarray:
        """(n,) volume [m^3] after growing each extent by ``pad`` [m]; with pad > 0, flat
        volumes (planar geometry) still compare by area. Builders minimise this."""
        raise NotImplementedError

    def size(self, bv: np.ndarray) -> np.ndarray:
        """(n,) a diameter [m]; traversals descend the larger of two volumes."""
        raise NotImplementedError

    def split_frame(self, tri: np.ndarray, starts, counts) -> tuple[np.ndarray, np.ndarray]:
        """Split directions for top-down building: (g, 3, 3) unit axes (rows, longest extent
        first) and (g, 3) the split centre, for triangle groups. Default: the bounding box of
        the group's vertices."""
        groups, _ = gather(tri.reshape(-1, 3), 3 * np.asarray(starts), 3 * np.asarray(counts))
        lo = groups.reduce(np.minimum, groups.points)
        hi = groups.reduce(np.maximum, groups.points)
        return box_axes_by_extent(lo, hi)

    def ray_interval(self, bv: np.ndarray, origin: np.ndarray, direction: np.ndarray,
                     margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Parameters (t_in, t_out), each (n,), where lines origin + t * direction are inside
        the grown volumes; t_in > t_out when the line misses."""
        raise NotImplementedError

    def distance_bound(self, bv: np.ndarray, points: np.ndarray) -> np.ndarray:
        """(n,) a lower bound of the distance [m] from points[i] to anything inside bv[i]."""
        raise NotImplementedError

    def contains(self, bv: np.ndarray, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """(n,) bool: points[i] lies in bv[i] grown by ``margin``."""
        return self.distance_bound(bv, points) <= margin

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r}>"


def slab_interval(lo, hi, o, d):
    """Per-slab parameter intervals of lines o + t d through slabs lo <= x <= hi, intersected
    over the last axis: (t_in, t_out). A line parallel to a slab is inside it for every t or
    for none."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ta = (lo - o) / d
        tb = (hi - o) / d
    parallel = d == 0.0
    inside = (o >= lo) & (o <= hi)
    t0 = np.where(parallel, np.where(inside, -np.inf, np.inf), np.minimum(ta, tb))
    t1 = np.where(parallel, np.where(inside, np.inf, -np.inf), np.maximum(ta, tb))
    return t0.max(axis=-1), t1.min(axis=-1)
