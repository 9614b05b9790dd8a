"""Triangle meshes as the collision library sees them: validated, read-only arrays.

Bad input policy (tested in ``tests/core/test_collision_bad_input.py``):

* non-finite vertex positions, out-of-range or non-integer indices, wrong shapes, and meshes
  without triangles raise :class:`~physanim.core.errors.PhysanimError` naming the mesh, the
  index and the value;
* degenerate (zero-area) triangles are kept: overlap tests treat them exactly as the segments or
  points they are; segments and rays pass through them (they have no area to hit); closest-point
  queries treat them as segments. :attr:`TriangleMesh.degenerate` flags them (exactly);
* open, non-manifold meshes and duplicate (coincident, unwelded) vertices need nothing special
  except for the sign of a distance, see :mod:`.distance`.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..transforms import cross
from ..errors import PhysanimError
from .tritri import normal_signs


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


def check_points(name: str, what: str, points, kind: str = "mesh") -> np.ndarray:
    """(n, 3) float64 copy of ``points``; raises naming the first non-finite one."""
    p = np.array(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise PhysanimError(f"{what} must be an (n, 3) array (got shape {p.shape})",
                            obj=name, kind=kind)
    bad = ~np.isfinite(p).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise PhysanimError(f"{what} {i} is not finite: {p[i].tolist()} "
                            f"({int(bad.sum())} such rows)", obj=name, kind=kind)
    return p


@dataclass(frozen=True, eq=False)
class TriangleMesh:
    """Vertices and triangles of one mesh in its local frame, validated and read-only.

    Args:
        vertices: (n_v, 3) positions [m].
        triangles: (n_t, 3) vertex indices (any winding; winding gives the face normals).
        name: used in every error message.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    name: str = "mesh"

    def __post_init__(self):
        v = check_points(self.name, "vertex", self.vertices)
        t = np.asarray(self.triangles)
        if t.ndim != 2 or t.shape[1] != 3:
            raise PhysanimError(f"triangles must be an (n, 3) array of vertex indices "
                                f"(got shape {t.shape})", obj=self.name, kind="mesh")
        if t.dtype.kind not in "iu" and t.size and not np.all(np.isfinite(t)
                                                              & (t == np.round(t))):
            raise PhysanimError("triangle vertex indices must be integers",
                                obj=self.name, kind="mesh")
        t = t.astype(np.int64)
        if len(t) == 0:
            raise PhysanimError("has no triangles to collide with", obj=self.name, kind="mesh")
        out = (t < 0) | (t >= len(v))
        if out.any():
            i = int(np.argmax(out.any(axis=1)))
            raise PhysanimError(f"triangle {i} refers to vertex {t[i].tolist()} but the mesh "
                                f"has {len(v)} vertices", obj=self.name, kind="mesh")
        object.__setattr__(self, "vertices", _frozen(v))
        object.__setattr__(self, "triangles", _frozen(t))

    @property
    def vertex_count(self) -> int:
        return len(self.vertices)

    @property
    def triangle_count(self) -> int:
        return len(self.triangles)

    def with_vertices(self, vertices) -> TriangleMesh:
        """The same triangles over new (deformed) vertex positions (n_v, 3) [m]."""
        v = check_points(self.name, "vertex", vertices)
        if v.shape != self.vertices.shape:
            raise PhysanimError(f"deformed vertices must keep the shape {self.vertices.shape} "
                                f"(got {v.shape})", obj=self.name, kind="mesh")
        return TriangleMesh(v, self.triangles, self.name)

    @cached_property
    def triangle_vertices(self) -> np.ndarray:
        """(n_t, 3, 3) corner positions of every triangle [m]."""
        return _frozen(self.vertices[self.triangles])

    @cached_property
    def degenerate(self) -> np.ndarray:
        """(n_t,) bool: the triangle has exactly zero area (its corners are collinear)."""
        return _frozen(~normal_signs(self.triangle_vertices).any(axis=1))

    @cached_property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) (3,) corners of the vertices' box [m]."""
        return _frozen(self.vertices.min(axis=0)), _frozen(self.vertices.max(axis=0))

    @cached_property
    def scale(self) -> float:
        """Largest absolute coordinate [m] (sets the size of rounding-safety pads)."""
        return float(np.abs(self.vertices).max()) if self.vertices.size else 0.0

    @cached_property
    def welded(self) -> np.ndarray:
        """(n_v,) index of the first vertex at exactly the same position (coincident vertices of
        unwelded meshes share one id)."""
        _, first, inverse = np.unique(self.vertices, axis=0, return_index=True,
                                      return_inverse=True)
        return _frozen(first[inverse.reshape(-1)])

    @cached_property
    def welded_corners(self) -> np.ndarray:
        """(n_t, 3) each triangle's corners by their :attr:`welded` ids."""
        return _frozen(self.welded[self.triangles])

    @cached_property
    def pseudo_normals(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Angle-weighted pseudo-normals (Baerentzen & Aanaes 2005) for the sign of distances.

        Coincident vertices are welded first, so unwelded seams do not open the surface. An
        edge's pseudo-normal is the sum of the unit normals of every face on it (one on an open
        boundary, more than two on a non-manifold edge); a vertex's sums its faces' unit normals
        weighted by the face angle there. Zero-area faces contribute nothing.

        Returns:
            (face (n_t, 3), edge (n_t, 3, 3), vertex (n_t, 3, 3)) unit vectors: face normals,
            the normal of each triangle's edge k (corner k -> k + 1), and of its corner k.
            Zero vectors where only zero-area faces meet.
        """
        tri = self.triangle_vertices
        face = cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        face = _unit(face)
        ids = self.welded[self.triangles]
        weight = np.empty((len(tri), 3))  # the face angle at each corner
        for k in range(3):
            u = _unit(tri[:, (k + 1) % 3] - tri[:, k])
            w = _unit(tri[:, (k + 2) % 3] - tri[:, k])
            weight[:, k] = np.arccos(np.clip(np.einsum("ij,ij->i", u, w), -1.0, 1.0))
        vert = _sum_by(ids.reshape(-1), (weight[:, :, None] * face[:, None, :]).reshape(-1, 3),
                       self.vertex_count)
        n = np.int64(self.vertex_count)
        a, b = ids, np.roll(ids, -1, axis=1)  # edge k joins corners k and k + 1
        key = (np.minimum(a, b) * n + np.maximum(a, b)).reshape(-1)
        _, inverse = np.unique(key, return_inverse=True)
        inverse = inverse.reshape(-1)
        edge = _sum_by(inverse, np.repeat(face, 3, axis=0), int(inverse.max()) + 1)
        per_edge = _unit(edge[inverse]).reshape(-1, 3, 3)
        per_vertex = _unit(vert[ids.reshape(-1)]).reshape(-1, 3, 3)
        for out in (face, per_edge, per_vertex):
            out.setflags(write=False)
        return face, per_edge, per_vertex

    @cached_property
    def feature_normals(self) -> np.ndarray:
        """(n_t * 7, 3) the pseudo-normals by feature: row 7 t + code is triangle t's face
        (code 0), edge k (code 1 + k) or corner k (code 4 + k), the codes of
        :mod:`.distance` — one gather per query."""
        face, edge, corner = self.pseudo_normals
        return _frozen(np.concatenate([face[:, None], edge, corner], axis=1).reshape(-1, 3))


    @cached_property
    def creases(self) -> tuple[np.ndarray, np.ndarray]:
        """The edges and corners that stand out of the surface: every edge (after welding)
        whose faces are not coplanar, or that borders fewer or more than two faces, and the
        vertices at their ends. Inside a flat region nothing stands out (a fanned cap's centre
        and spokes, a quad's diagonal), so what touches such a region only touches its faces.

        Returns:
            (edges (e, 2) vertex ids, vertices (k,) ids), welded ids, sorted.
        """
        ids = self.welded[self.triangles]
        n = np.int64(self.vertex_count)
        a, b = ids, np.roll(ids, -1, axis=1)
        key = (np.minimum(a, b) * n + np.maximum(a, b)).reshape(-1)
        keys, first, inverse, counts = np.unique(key, return_index=True, return_inverse=True,
                                                 return_counts=True)
        face = np.repeat(self.pseudo_normals[0], 3, axis=0)
        # coplanar faces: every face of the edge has the normal of its first
        bent = np.zeros(len(keys), bool)
        np.logical_or.at(bent, inverse, np.einsum("ij,ij->i", face, face[first[inverse]])
                         < 1.0 - 1e-9)
        sharp = bent | (counts != 2)
        edges = np.stack([keys[sharp] // n, keys[sharp] % n], axis=1)
        return _frozen(edges), _frozen(np.unique(edges))


def _sum_by(index: np.ndarray, values: np.ndarray, count: int) -> np.ndarray:
    """(count, 3) sums of (m, 3) ``values`` grouped by ``index`` (m,)."""
    return np.stack([np.bincount(index, weights=values[:, k], minlength=count)
                     for k in range(3)], axis=1)


def _unit(v: np.ndarray) -> np.ndarray:
    """Rows of ``v`` scaled to unit length; zero rows stay zero."""
    length = np.sqrt(np.einsum("ij,ij->i", v, v))
    return v / np.where(length > 0.0, length, 1.0)[:, None]
