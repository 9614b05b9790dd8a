"""The mesh colliders' hierarchies kept between frame intervals of a run (one per collider,
refitted while its triangles stay the same), with their open-boundary features and grids:
what :class:`.mesh.MeshPath` asks for each interval."""
from __future__ import annotations

import numpy as np

from ..collision.build import build_bvh
from ..collision.bvh import BVH
from ..collision.cells import TriangleCells
from ..collision.distance import CORNER, EDGE
from ..collision.mesh import TriangleMesh
from .frame import ColliderFrame

BVH_KIND = "aabb"  # refits cheaply and exactly for deforming meshes
HIERARCHY_CACHE = 8  # colliders remembered between frame intervals
REBUILD_AFTER = 24  # refits before a deforming mesh's hierarchy is built afresh (its splits
#                     were chosen for the shape it had then)


class MeshHierarchies:
    """Mesh-collider hierarchies kept between frame intervals, owned by the caller (a bake keeps
    one for its run and drops it with the run, so large meshes do not stay in memory).

    Consecutive frame intervals of one collider usually share its mesh: the same vertices (a
    rigid collider: only the object matrix moves) reuse the hierarchy, moved vertices over the
    same triangles (a deforming mesh) refit it — building one costs ~100x a refit — and every
    REBUILD_AFTER refits it is built afresh for the current shape. Reuse is decided by
    comparing the arrays, never by name alone.
    """

    def __init__(self, capacity: int = HIERARCHY_CACHE):
        self.capacity = capacity
        self._known: dict = {}  # collider name -> (triangles, vertices, BVH, boundary, refits)
        self._cells: dict = {}  # collider name -> (BVH, its grid)

    def in_use(self, count: int) -> None:
        """``count`` mesh colliders take part in the frame interval being made: every one of
        them is kept, and every one of those asked for just before (a frame asks once for the
        scene's colliders, then again with the rigid bodies'), at least ``capacity``: a cache
        of fewer would build each one's hierarchy again every frame."""
        self._in_use = max(count, getattr(self, "_asked", 0))
        self._asked = count

    def _keep(self, table: dict, name: str, value) -> None:
        """``table[name] = value``, last (the most recently used); a new name first makes room
        by dropping the least recently used beyond what is kept."""
        if table.pop(name, None) is None:
            limit = max(self.capacity, getattr(self, "_in_use", 0))
            while table and len(table) >= limit:
                table.pop(next(iter(table)))
        table[name] = value

    def __len__(self) -> int:
        return len(self._known)

    def clear(self) -> None:
        self._known.clear()
        self._cells.clear()

    def cells(self, name: str, bvh: BVH) -> TriangleCells:
        """The grid over ``bvh``'s triangles (built on first use, kept while the hierarchy is)."""
        known = self._cells.get(name)
        if known is None or known[0] is not bvh:
            known = (bvh, TriangleCells(bvh))
        self._keep(self._cells, name, known)  # (the most recently used last)
        return known[1]

    def of(self, frame: ColliderFrame) -> tuple[BVH, np.ndarray]:
        """The hierarchy and open-boundary features of a collider mesh at the interval's start."""
        tris, verts = frame.triangles, frame.vertices0
        known = self._known.get(frame.name)
        if known is not None and known[0].shape == tris.shape and np.array_equal(known[0], tris):
            if known[1].shape == verts.shape and np.array_equal(known[1], verts):
                self._keep(self._known, frame.name, known)  # (the most recently used last)
                return known[2], known[3]
            if known[1].shape == verts.shape and known[4] < REBUILD_AFTER:
                bvh, _ = known[2].refit(verts)
                boundary = _boundary_features(bvh.mesh)  # welding may change as vertices move
                self._keep(self._known, frame.name,
                           (known[0], verts.copy(), bvh, boundary, known[4] + 1))
                return bvh, boundary
        bvh = build_bvh(TriangleMesh(verts, tris, frame.name), BVH_KIND, "topdown")
        boundary = _boundary_features(bvh.mesh)
        self._keep(self._known, frame.name, (tris.copy(), verts.copy(), bvh, boundary, 0))
        return bvh, boundary


def _boundary_features(mesh: TriangleMesh) -> np.ndarray:
    """(m, 7) bool by feature code (see :mod:`..collision.distance`): the triangle's edge or
    corner lies on an open boundary (an edge of only one triangle, after welding)."""
    ids = mesh.welded[mesh.triangles]
    n = np.int64(mesh.vertex_count)
    a, b = ids, np.roll(ids, -1, axis=1)  # edge k joins corners k and k + 1
    key = (np.minimum(a, b) * n + np.maximum(a, b)).reshape(-1)
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    edge_open = (counts[inverse.reshape(-1)] == 1).reshape(-1, 3)
    vertex_open = np.zeros(mesh.vertex_count, dtype=bool)
    vertex_open[a[edge_open]] = True
    vertex_open[b[edge_open]] = True
    out = np.zeros((mesh.triangle_count, 7), dtype=bool)
    out[:, EDGE:EDGE + 3] = edge_open
    out[:, CORNER:CORNER + 3] = vertex_open[ids]
    return out
