"""Oriented bounding boxes: covariance fits and the separating-axis overlap test.

Layout: (n, 15) rows ``[centre (3), axes (3 x 3, row i = unit axis i), half-extents (3)]``.

The box axes are the eigenvectors of a covariance matrix; the extents then come from projecting
every point on them. The seed gives two covariances, and hierarchies may use a third:

* ``"vertices"``: covariance of the points themselves. Cheap, but biased by how densely a part of
  the surface is sampled, and by interior points.
* ``"hull"``: covariance of the surface of the points' convex hull, each hull triangle weighted
  by its area (Gottschalk's continuous formula; :mod:`.hull`). Insensitive to sampling density
  and interior points, at the price of a quickhull per group (a Python loop over groups).
* ``"triangles"``: the same area-weighted formula over the mesh's own triangles of each group
  rather than the hull's: vectorised over all groups, and the hull method's answer whenever
  the group is convex.

Refitting a deformed hierarchy keeps each box's axes and recomputes its centre and extents.
"""
from __future__ import annotations

import numpy as np

from ..transforms import cross
from .bounding import BoundingVolume, Groups, gather, linear_part, similarity_scale, slab_interval
from .hull import convex_hull
from .sat import obb_overlap

METHODS = ("vertices", "hull", "triangles")


def unpack(bv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(centre (n, 3), axes (n, 3, 3) rows, half-extents (n, 3)) of packed boxes (n, 15)."""
    return bv[:, :3], bv[:, 3:12].reshape(-1, 3, 3), bv[:, 12:15]


def pack(centre: np.ndarray, axes: np.ndarray, half: np.ndarray) -> np.ndarray:
    return np.concatenate([centre, axes.reshape(-1, 9), half], axis=1)


def axes_from_covariance(cov: np.ndarray) -> np.ndarray:
    """(g, 3, 3) right-handed orthonormal axes (rows, decreasing variance) of (g, 3, 3)
    symmetric covariance matrices."""
    _, vec = np.linalg.eigh(cov)
    axes = np.swapaxes(vec[..., ::-1], 1, 2).copy()
    flip = np.linalg.det(axes) < 0.0
    axes[flip, 2] *= -1.0
    return axes


def vertex_covariance(groups: Groups) -> np.ndarray:
    """(g, 3, 3) covariance of each group's points (relative to its first point, for accuracy)."""
    q = groups.points - groups.spread(groups.points[groups.first])
    n = groups.counts[:, None].astype(np.float64)
    mean = groups.reduce(np.add, q) / n
    second = groups.reduce(np.add, q[:, :, None] * q[:, None, :]) / n[:, :, None]
    return second - mean[:, :, None] * mean[:, None, :]


def surface_covariance(tri: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Area-weighted covariance of the surface of each group of triangles.

    For a triangle (p, q, r) of area A and centroid m, the second moment of its surface is
    A / 12 (9 m m^T + p p^T + q q^T + r r^T); summing over a group and dividing by the total
    area A_H gives E[x x^T], from which the area-weighted mean's outer product is subtracted.

    Args:
        tri: (m, 3, 3) triangles gathered by group.
        offsets: (g + 1,) group boundaries in ``tri``.

    Returns:
        (covariance (g, 3, 3), total area (g,) [m^2]).
    """
    groups = Groups(tri[:, 0], offsets)
    q = tri - groups.spread(tri[offsets[:-1], 0])[:, None, :]
    cr = cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])
    area = 0.5 * np.sqrt(np.einsum("ij,ij->i", cr, cr))
    cen = q.mean(axis=1)
    moment = (9.0 * cen[:, :, None] * cen[:, None, :]
              + np.einsum("nki,nkj->nij", q, q)) * (area / 12.0)[:, None, None]
    total = groups.reduce(np.add, area)
    safe = np.where(total > 0.0, total, 1.0)
    mean = groups.reduce(np.add, cen * area[:, None]) / safe[:, None]
    cov = groups.reduce(np.add, moment) / safe[:, None, None]
    return cov - mean[:, :, None] * mean[:, None, :], total


class OBB(BoundingVolume):
    """Oriented bounding box kind.

    Args:
        method: covariance used for the axes: ``"vertices"``, ``"hull"`` or ``"triangles"``
            (see the module docstring; bare point sets use ``"vertices"`` for ``"triangles"``).
        sat_axes: 15 for the exact separating-axis test, 6 for the faster face-axes-only one.
    """

    width = 15

    def __init__(self, method: str = "vertices", sat_axes: int = 15, name: str | None = None):
        if method not in METHODS:
            raise ValueError(f"OBB fit method must be one of {METHODS} (got {method!r})")
        if sat_axes not in (6, 15):
            raise ValueError(f"OBB sat_axes must be 15 or 6 (got {sat_axes})")
        self.method = method
        self.sat_axes = sat_axes
        self.name = name or "obb"

    # --- fitting ---------------------------------------------------------------------------
    def fit_groups(self, groups: Groups) -> np.ndarray:
        if self.method == "hull":
            return self._fit_extents(groups, self._hull_axes(groups))
        return self._fit_extents(groups, axes_from_covariance(vertex_covariance(groups)))

    def fit_triangles(self, tri, starts, counts):
        if self.method != "triangles":
            return super().fit_triangles(tri, starts, counts)
        groups, _ = gather(tri.reshape(-1, 3), 3 * np.asarray(starts), 3 * np.asarray(counts))
        cov, area = surface_covariance(groups.points.reshape(-1, 3, 3), groups.offsets // 3)
        flat = area <= 0.0
        if flat.any():  # zero-area groups: fall back to the vertices
            cov[flat] = vertex_covariance(groups)[flat]
        return self._fit_extents(groups, axes_from_covariance(cov))

    def refit_triangles(self, bv, tri, starts, counts):
        groups, _ = gather(tri.reshape(-1, 3), 3 * np.asarray(starts), 3 * np.asarray(counts))
        return self._fit_extents(groups, unpack(bv)[1])

    def _hull_axes(self, groups: Groups) -> np.ndarray:
        covs = []
        for i in range(groups.group_count):
            pts = groups.points[groups.offsets[i]:groups.offsets[i + 1]]
            hull = convex_hull(pts)
            if hull.dimension >= 2:
                cov, _ = surface_covariance(hull.points[hull.triangles],
                                            np.array([0, len(hull.triangles)]))
                covs.append(cov[0])
            else:
                covs.append(vertex_covariance(Groups(pts, np.array([0, len(pts)])))[0])
        return axes_from_covariance(np.array(covs))

    @staticmethod
    def _fit_extents(groups: Groups, axes: np.ndarray) -> np.ndarray:
        ref = groups.points[groups.first]
        local = np.einsum("mij,mj->mi", groups.spread(axes), groups.points - groups.spread(ref))
        lo = groups.reduce(np.minimum, local)
        hi = groups.reduce(np.maximum, local)
        centre = ref + np.einsum("gi,gij->gj", 0.5 * (lo + hi), axes)
        return pack(centre, axes, 0.5 * (hi - lo))

    # --- tests -----------------------------------------------------------------------------
    def overlap(self, a, b, margin=0.0):
        ca, ra, ha = unpack(a)
        cb, rb, hb = unpack(b)
        return obb_overlap(ca, ra, ha, cb, rb, hb, margin, self.sat_axes)

    def to_local(self, bv, points, vectors=False):
        """Points (or vectors) (n, 3) in the frames of boxes (n, 15)."""
        c, axes, _ = unpack(bv)
        v = points if vectors else points - c
        return np.einsum("nij,nj->ni", axes, v)

    def ray_interval(self, bv, origin, direction, margin=0.0):
        h = unpack(bv)[2] + margin
        return slab_interval(-h, h, self.to_local(bv, origin),
                             self.to_local(bv, direction, vectors=True))

    def distance_bound(self, bv, points):
        excess = np.maximum(np.abs(self.to_local(bv, points)) - unpack(bv)[2], 0.0)
        return np.sqrt(np.einsum("ij,ij->i", excess, excess))

    # --- construction helpers --------------------------------------------------------------
    def transform(self, bv, matrix):
        """Exact for similarity transforms (the only ones that keep a box a box)."""
        s = similarity_scale(matrix)
        a, t = linear_part(matrix)
        c, axes, half = unpack(np.asarray(bv, dtype=np.float64))
        return pack(c @ a.T + t, axes @ (a / s).T, half * s)

    def merge(self, a, b):
        """A box with the axes of the larger of the two, grown over the other's extent (the
        other box projects onto axis a_i as t_i +- sum_j h_j |a_i . b_j|)."""
        bigger = (self.volume(a) >= self.volume(b))[:, None]
        c, axes, half = unpack(np.where(bigger, a, b))
        co, axes_o, half_o = unpack(np.where(bigger, b, a))
        t = np.matmul(axes, (co - c)[:, :, None])[:, :, 0]
        r = np.matmul(np.abs(np.matmul(axes, axes_o.transpose(0, 2, 1))), half_o[:, :, None])
        lo = np.minimum(-half, t - r[:, :, 0])
        hi = np.maximum(half, t + r[:, :, 0])
        centre = c + np.matmul((0.5 * (lo + hi))[:, None, :], axes)[:, 0]
        return pack(centre, axes, 0.5 * (hi - lo))

    @staticmethod
    def corners(bv) -> np.ndarray:
        """(n, 8, 3) corner points of boxes."""
        c, axes, half = unpack(bv)
        signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
        return c[:, None, :] + np.einsum("kj,nj,nji->nki", signs, half, axes)

    def measure(self, bv, pad):
        return np.prod(2.0 * bv[:, 12:15] + pad, axis=1)

    def size(self, bv):
        return 2.0 * np.sqrt(np.einsum("ij,ij->i", bv[:, 12:15], bv[:, 12:15]))

    def split_frame(self, tri, starts, counts):
        bv = self.fit_triangles(tri, starts, counts)
        c, axes, half = unpack(bv)
        order = np.argsort(-half, axis=1, kind="stable")
        return np.take_along_axis(axes, order[:, :, None], axis=1), c
