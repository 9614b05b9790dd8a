"""3D convex hull by quickhull (Barber, Dobkin & Huhdanpaa 1996), for OBB fitting.

Robustness: duplicate points are removed first; a point counts as outside a face only when it is
more than ``tolerance`` [m] above the face's plane (default: a few hundred ulps of the
coordinates' magnitude), so coplanar and nearly coplanar points never create slivers or break
the horizon. The hull therefore contains every input point to within ``tolerance``.
Point sets of lower dimension give a lower-dimensional hull: a flat polygon (fan-triangulated,
dimension 2), a segment or a point (no triangles, dimension 1 or 0).

The loop adds one hull vertex per iteration (farthest point of a face's outside set, flood fill
of the faces it sees, new faces on the horizon); assigning points to faces is vectorised.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import cross
from .mesh import check_points

TOLERANCE_REL = 256 * 2.0 ** -52


@dataclass(frozen=True)
class ConvexHull:
    """Convex hull of a point set.

    Attributes:
        points: (n, 3) the input points [m].
        triangles: (f, 3) indices into ``points``, counter-clockwise seen from outside
            (dimension 3) or around the plane normal of a flat hull (dimension 2).
        dimension: 0 (a point), 1 (a segment), 2 (a flat polygon) or 3.
        vertices: (h,) sorted indices of the hull's corner points.
        tolerance: distance [m] within which points count as on a face.
    """

    points: np.ndarray
    triangles: np.ndarray
    dimension: int
    vertices: np.ndarray
    tolerance: float

    @property
    def area(self) -> float:
        """Surface area [m^2] (one side of a flat hull)."""
        t = self.points[self.triangles]
        return float(0.5 * np.linalg.norm(cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]),
                                          axis=1).sum())

    @property
    def volume(self) -> float:
        """Enclosed volume [m^3] (0 below dimension 3)."""
        if self.dimension < 3:
            return 0.0
        t = self.points[self.triangles] - self.points[self.vertices[0]]
        return float(np.einsum("ij,ij->i", t[:, 0], cross(t[:, 1], t[:, 2])).sum() / 6.0)


def convex_hull(points, tolerance: float | None = None) -> ConvexHull:
    """Convex hull of (n, 3) points [m]; see the module docstring for the tolerance policy."""
    p = check_points("convex hull", "point", points, kind="input")
    if len(p) == 0:
        raise ValueError("convex hull of no points")
    _, keep = np.unique(p, axis=0, return_index=True)
    keep = np.sort(keep)
    q = p[keep]
    scale = float(np.abs(q).max(axis=0).sum())
    tol = TOLERANCE_REL * max(scale, 1e-300) if tolerance is None else float(tolerance)
    dim, simplex = _initial_simplex(q, tol)
    if dim == 3:
        tris = _Quickhull(q, tol, simplex).run()
    elif dim == 2:
        tris = _flat_hull(q, simplex, tol)
    else:
        tris = np.zeros((0, 3), dtype=np.int64)
    if dim >= 2:
        corners = np.unique(tris)
    else:
        corners = np.unique(np.asarray(simplex[:dim + 1]))
    return ConvexHull(p, keep[tris], dim, np.sort(keep[corners]), tol)


def _initial_simplex(q: np.ndarray, tol: float) -> tuple[int, list[int]]:
    ext = np.concatenate([q.argmin(axis=0), q.argmax(axis=0)])
    d = q[ext][:, None, :] - q[ext][None, :, :]
    i, j = np.unravel_index(np.argmax(np.einsum("ijk,ijk->ij", d, d)), d.shape[:2])
    a, b = int(ext[i]), int(ext[j])
    if np.linalg.norm(q[b] - q[a]) <= tol:
        return 0, [a]
    axis = (q[b] - q[a]) / np.linalg.norm(q[b] - q[a])
    rel = q - q[a]
    off = rel - np.outer(rel @ axis, axis)
    c = int(np.argmax(np.einsum("ij,ij->i", off, off)))
    if np.linalg.norm(off[c]) <= tol:
        return 1, [a, b]
    normal = cross(q[b] - q[a], q[c] - q[a])
    normal /= np.linalg.norm(normal)
    height = rel @ normal
    e = int(np.argmax(np.abs(height)))
    if abs(height[e]) <= tol:
        return 2, [a, b, c]
    return 3, [a, b, c, e]


def _flat_hull(q: np.ndarray, simplex: list[int], tol: float) -> np.ndarray:
    """Fan triangulation of the 2D hull of coplanar points (Andrew's monotone chain)."""
    a, b, c = simplex
    u = (q[b] - q[a]) / np.linalg.norm(q[b] - q[a])
    n = cross(q[b] - q[a], q[c] - q[a])
    n /= np.linalg.norm(n)
    v = cross(n, u)
    xy = np.stack([(q - q[a]) @ u, (q - q[a]) @ v], axis=1)
    order = np.lexsort((xy[:, 1], xy[:, 0]))

    def chain(idx):
        out: list[int] = []
        for k in idx:
            while len(out) >= 2:
                o, p1 = xy[out[-2]], xy[out[-1]]
                cross = (p1[0] - o[0]) * (xy[k][1] - o[1]) - (p1[1] - o[1]) * (xy[k][0] - o[0])
                if cross > tol * np.linalg.norm(xy[k] - o):
                    break
                out.pop()
            out.append(int(k))
        return out

    lower, upper = chain(order), chain(order[::-1])
    ring = lower[:-1] + upper[:-1]
    return np.array([[ring[0], ring[i], ring[i + 1]] for i in range(1, len(ring) - 1)],
                    dtype=np.int64).reshape(-1, 3)


class _Quickhull:
    """Mutable working state of one hull computation (faces, edge map, outside sets)."""

    def __init__(self, q: np.ndarray, tol: float, simplex: list[int]):
        self.q = q
        self.rows = q.tolist()  # plain floats: per-face arithmetic is faster without numpy
        self.tol = tol
        cap = 64
        self.verts = np.zeros((cap, 3), dtype=np.int64)
        self.normal = np.zeros((cap, 3))
        self.offset = np.zeros(cap)
        self.alive = np.zeros(cap, dtype=bool)
        self.count = 0
        self.edge: dict[tuple[int, int], int] = {}
        self.outside: dict[int, np.ndarray] = {}
        a, b, c, d = simplex
        if np.dot(cross(q[b] - q[a], q[c] - q[a]), q[d] - q[a]) > 0.0:
            b, c = c, b  # make (a, b, c) face away from d
        faces = [self._add(a, b, c), self._add(a, d, b), self._add(b, d, c), self._add(c, d, a)]
        rest = np.setdiff1d(np.arange(len(q)), simplex)
        self._assign(rest, faces)

    def _add(self, a: int, b: int, c: int) -> int:
        if self.count == len(self.alive):
            grow = len(self.alive)
            self.verts = np.concatenate([self.verts, np.zeros((grow, 3), dtype=np.int64)])
            self.normal = np.concatenate([self.normal, np.zeros((grow, 3))])
            self.offset = np.concatenate([self.offset, np.zeros(grow)])
            self.alive = np.concatenate([self.alive, np.zeros(grow, dtype=bool)])
        f = self.count
        self.count += 1
        (ax, ay, az), (bx, by, bz), (cx, cy, cz) = self.rows[a], self.rows[b], self.rows[c]
        ux, uy, uz, vx, vy, vz = bx - ax, by - ay, bz - az, cx - ax, cy - ay, cz - az
        nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
        length = (nx * nx + ny * ny + nz * nz) ** 0.5
        if length > 0.0:
            nx, ny, nz = nx / length, ny / length, nz / length
        else:  # a sliver sees nothing
            nx = ny = nz = 0.0
        n = (nx, ny, nz)
        self.verts[f] = (a, b, c)
        self.normal[f] = n
        self.offset[f] = nx * ax + ny * ay + nz * az
        self.alive[f] = True
        for e in ((a, b), (b, c), (c, a)):
            self.edge[e] = f
        return f

    def _height(self, point: int, face: int) -> float:
        x, y, z = self.rows[point]
        nx, ny, nz = self.normal[face]
        return x * nx + y * ny + z * nz - self.offset[face]

    def _assign(self, pts: np.ndarray, faces: list[int]) -> None:
        if len(pts) == 0:
            return
        fa = np.asarray(faces)
        h = self.q[pts] @ self.normal[fa].T - self.offset[fa]
        best = np.argmax(h, axis=1)
        out = h[np.arange(len(pts)), best] > self.tol
        for k, f in enumerate(faces):
            mine = pts[out & (best == k)]
            if len(mine):
                self.outside[f] = mine

    def run(self) -> np.ndarray:
        pending = list(self.outside)
        while pending:
            f = pending.pop()
            if not self.alive[f] or f not in self.outside:
                continue
            pts = self.outside[f]
            ip = int(pts[np.argmax(self.q[pts] @ self.normal[f])])
            visible, horizon = self._horizon(ip, f)
            loose = [self.outside.pop(g) for g in visible if g in self.outside]
            for g in visible:
                self.alive[g] = False
                a, b, c = self.verts[g]
                for e in ((a, b), (b, c), (c, a)):
                    if self.edge.get((int(e[0]), int(e[1]))) == g:
                        del self.edge[(int(e[0]), int(e[1]))]
            new = [self._add(a, b, ip) for a, b in horizon]
            pts = np.concatenate(loose) if loose else np.zeros(0, dtype=np.int64)
            self._assign(pts[pts != ip], new)
            pending.extend(g for g in new if g in self.outside)
        return self.verts[:self.count][self.alive[:self.count]]

    def _horizon(self, ip: int, start: int) -> tuple[list[int], list[tuple[int, int]]]:
        """Faces that see ``ip`` (flood fill from ``start``) and the boundary edges of that
        region, directed as in the visible faces."""
        visible = {start}
        stack = [start]
        horizon = []
        while stack:
            f = stack.pop()
            a, b, c = (int(x) for x in self.verts[f])
            for e in ((a, b), (b, c), (c, a)):
                g = self.edge[(e[1], e[0])]
                if g in visible:
                    continue
                if self._height(ip, g) > self.tol:
                    visible.add(g)
                    stack.append(g)
                else:
                    horizon.append(e)
        # an edge found from a face later added to the region is not on the horizon
        horizon = [e for e in horizon if self.edge[(e[1], e[0])] not in visible]
        return sorted(visible), horizon
