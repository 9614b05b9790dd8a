"""A rigid mesh's parts the contact search reads again and again, built once per mesh: its edges
(:class:`MeshEdges`) and its vertices hashed by cells (:class:`VertexCells`), so that a search
near a few bodies reads the vertices near them, not every vertex of a terrain."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

_PRIME = np.array([73856093, 19349663, 83492791], np.int64)
_AROUND = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)])


@dataclass(frozen=True)
class MeshEdges:
    """A mesh's edges, each once: (e, 2) vertex pairs, the longest one's length [m], and for
    each vertex the edges that end there (``around[start[v]:start[v + 1]]``)."""

    pairs: np.ndarray
    longest: float
    start: np.ndarray
    around: np.ndarray

    @classmethod
    def of(cls, vertices: np.ndarray, triangles: np.ndarray) -> MeshEdges:
        t = np.asarray(triangles, np.int64).reshape(-1, 3)
        both = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
        pairs = np.unique(np.sort(both, axis=1), axis=0)
        length = np.linalg.norm(vertices[pairs[:, 1]] - vertices[pairs[:, 0]], axis=1)
        ends = pairs.ravel()
        order = np.argsort(ends, kind="stable")
        start = np.searchsorted(ends[order], np.arange(len(vertices) + 1))
        return cls(pairs, float(length.max(initial=0.0)), start, order // 2)

    def touching(self, vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(which (k,), edge (k,)): the edges ending at each of ``vertices``."""
        count = self.start[vertices + 1] - self.start[vertices]
        which = np.repeat(np.arange(len(vertices)), count)
        at = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
        return which, self.around[np.repeat(self.start[vertices], count) + at]


class PointCells:
    """Points hashed by cubic cells of one size (sorted by their cells' hashes): the points
    within a radius of a centre are read from the 27 cells around it (radii up to the cell)."""

    def __init__(self, points: np.ndarray, cell: float):
        self.points, self.cell = points, cell
        keys = _hashed(np.floor(points / cell).astype(np.int64))
        self.order = np.argsort(keys, kind="stable")
        self.keys = keys[self.order]

    def near(self, centres: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(k, v) index pairs: points[v] closer than radii[k] (each at most the cell) to
        centres[k] (K, 3)."""
        ask = _hashed(np.floor(centres / self.cell).astype(np.int64)[:, None] + _AROUND).ravel()
        lo = np.searchsorted(self.keys, ask, "left")
        count = np.searchsorted(self.keys, ask, "right") - lo
        body = np.repeat(np.arange(len(ask)) // len(_AROUND), count)
        at = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
        vertex = self.order[np.repeat(lo, count) + at]
        close = np.linalg.norm(self.points[vertex] - centres[body], axis=1) < radii[body]
        n = len(self.points)
        pair = np.unique(body[close] * n + vertex[close])  # hashes may repeat cells
        return pair // n, pair % n


@dataclass
class VertexCells:
    """A rigid mesh's vertices (in its own frame) hashed by cells whose sizes are powers of
    two, each size built the first time a search asks for it and kept with the mesh."""

    vertices: np.ndarray
    _by_size: dict = field(default_factory=dict)
    _bounds: tuple | None = None

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) (3,) of the vertices."""
        if self._bounds is None:
            self._bounds = (self.vertices.min(axis=0), self.vertices.max(axis=0))
        return self._bounds

    def near(self, centres: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(k, v) index pairs: vertices[v] closer than radii[k] to centres[k] (K, 3), both in
        the mesh's frame."""
        if not len(centres) or not len(self.vertices):
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        cell = 2.0 ** math.ceil(math.log2(max(float(radii.max()), 1e-6)))
        cells = self._by_size.get(cell)
        if cells is None:
            cells = self._by_size[cell] = PointCells(self.vertices, cell)
        return cells.near(centres, radii)


def _hashed(ijk: np.ndarray) -> np.ndarray:
    h = ijk * _PRIME
    return h[..., 0] ^ h[..., 1] ^ h[..., 2]
