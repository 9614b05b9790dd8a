"""A uniform grid over a mesh's triangles, for queries over small regions (many particles each
asking about a few millimetres of surface).

A hierarchy answers a query by descending some twenty levels; a grid answers one by looking up
the few cells its region (a segment's box, a point's ball's box) overlaps. Each cell lists every
triangle whose bounding box meets the closed cell. Cell coordinates are floor((x - origin) *
(1 / cell_size)) for triangles and queries alike, a non-decreasing function of x: a triangle
whose box meets a query's box at a point x is listed in the cell holding x, which the query
looks up. The lists are therefore a superset of the triangles the hierarchy would reach, and the
exact tests that follow decide the same answer (a triangle met in two cells is tested twice, to
the same result). Regions over more than ``QUERY_CELLS`` cells (long segments) are left to the
hierarchy.

The cell edge is a third of the median triangle's longest box side, so that a resting or slow
particle's region looks up one or two cells listing a few triangles; it grows while the lists
would hold more than ``MAX_ENTRIES`` entries per triangle. Triangles spanning more than
``LARGE_CELLS`` cells (a floor under a detailed mesh) are not entered; every query tests them
instead, which is cheap while they are few (at most ``MAX_LARGE``; a mesh with more gets no grid).

A cell is larger than a resting particle's region, so the candidates are the listed triangles
whose boxes meet the query's box.
"""
from __future__ import annotations

import numpy as np

from ..transforms import take
from .broadphase_grid import _entries, _keys
from .bvh import BVH

CELL = 1 / 3  # cell edge, in median triangle box sides
QUERY_CELLS = 27  # a query over more cells than this is left to the hierarchy
LARGE_CELLS = 64  # triangles overlapping more cells than this are tested by every query
MAX_LARGE = 64  # more large triangles than this: no grid
MAX_ENTRIES = 32  # (triangle, cell) entries per triangle on average; more: larger cells


class TriangleCells:
    """The grid over a hierarchy's triangles (positions in its leaf order), or ``usable`` False
    when the mesh does not suit one (see the module docstring).

    Attributes:
        cell_size: [m] in the mesh's frame.
        usable: whether queries may use the grid.
    """

    def __init__(self, bvh: BVH):
        self.bvh = bvh
        tri = bvh.ordered_triangles
        live = ~bvh.mesh.degenerate[bvh.tri_order]
        self.usable = False
        if len(tri) == 0:
            return
        lo, hi = tri.min(axis=1), tri.max(axis=1)
        extent = (hi - lo).max(axis=1)
        size = CELL * float(np.median(extent[live])) if live.any() else 0.0
        if not size > 0.0:
            size = float(extent.max())
        if not size > 0.0:
            return
        while True:
            origin = lo.min(axis=0) - 2.0 * size  # cell 0 (and dims - 1) stays empty
            first = np.floor((lo - origin) * (1.0 / size)).astype(np.int64)
            last = np.floor((hi - origin) * (1.0 / size)).astype(np.int64)
            span = last - first + 1
            count = span.prod(axis=1)
            large = count > LARGE_CELLS
            if large.sum() <= MAX_LARGE and count[~large].sum() <= MAX_ENTRIES * len(tri):
                break
            size *= 2.0  # ends: once a cell spans the mesh, every triangle is in a few
        self.cell_size, self.origin = size, origin
        self.dims = (last.max(axis=0) + 2).astype(np.int64)
        if float(np.prod(self.dims.astype(float))) >= 2.0 ** 62:
            return
        owner, cell = _entries(np.nonzero(~large)[0], first, span)
        key = _keys(cell, self.dims)[0]
        order = np.argsort(key, kind="stable")
        key = key[order]
        index = np.int32 if len(tri) < 2 ** 31 and len(key) < 2 ** 31 else np.int64  # memory
        self.entries = owner[order].astype(index)
        self.keys, starts = np.unique(key, return_index=True)
        self.starts = starts.astype(index)
        self.ends = np.append(starts[1:], len(key)).astype(index)
        self._slots = _hash_table(self.keys)
        self.large = np.nonzero(large)[0]
        self._box = np.concatenate([lo, -hi], axis=1)  # [lo, -hi]: one gather, one compare
        self.usable = True

    def _cell(self, x: np.ndarray) -> np.ndarray:
        """Cell coordinates of points x (n, 3) as the triangles' were computed, clamped to the
        grid's border cells, which hold no triangle (the grid has one empty cell on each side),
        so that a query reaching outside looks up empty cells there."""
        # by columns (numpy broadcasts the (3,) origin and bounds over (n, 3) row by row)
        u = np.empty((len(x), 3), np.int64)
        scale = 1.0 / self.cell_size
        for j in range(3):
            c = np.subtract(x[:, j], self.origin[j])
            c *= scale
            np.maximum(c, 0.0, out=c)
            np.minimum(c, self.dims[j] - 1.0, out=c)
            u[:, j] = c  # truncation is floor for c >= 0
        return u

    def candidates(self, lo: np.ndarray, hi: np.ndarray):
        """Candidate triangles of query boxes [lo, hi] (n, 3).

        Returns (query (k,), position (k,), rest): pairs of a query and a triangle position in
        the hierarchy's leaf order for the queries over at most ``QUERY_CELLS`` cells, and the
        indices of the other queries (for the hierarchy).
        """
        first, last = self._cell(lo), self._cell(hi)
        span = last - first + 1
        count = span[:, 0] * span[:, 1] * span[:, 2]  # (a reduction along 3 is slow in numpy)
        use = count <= QUERY_CELLS
        ok = np.nonzero(use)[0]
        query, cell = _entries(ok, first, span)
        at = _look_up(self._slots, self.keys, _keys(cell, self.dims)[0])
        found = at >= 0
        query, at = query[found], at[found]
        start, many = self.starts[at], self.ends[at] - self.starts[at]
        pos = self.entries[np.repeat(start - np.cumsum(many) + many, many)
                           + np.arange(many.sum())]
        query = np.repeat(query, many)
        if len(self.large):
            query = np.concatenate([query, np.repeat(ok, len(self.large))])
            pos = np.concatenate([pos, np.tile(self.large, len(ok))])
        # the boxes themselves (a cell is larger than a resting particle's region)
        meet = take(self._box, pos) <= take(np.concatenate([hi, -lo], axis=1), query)
        meet = meet[:, 0] & meet[:, 1] & meet[:, 2] & meet[:, 3] & meet[:, 4] & meet[:, 5]
        return query[meet], pos[meet], np.nonzero(~use)[0]


_GOLDEN = np.uint64(0x9E3779B97F4A7C15)  # odd multiplier of the hash (Fibonacci hashing)


def _slot_of(key: np.ndarray, bits: int) -> np.ndarray:
    with np.errstate(over="ignore"):
        return ((key.astype(np.uint64) * _GOLDEN) >> np.uint64(64 - bits)).astype(np.int64)


def _hash_table(keys: np.ndarray) -> tuple[int, np.ndarray]:
    """An open-addressing table (linear probing, at most half full) of ``keys``' indices:
    (bits, slots), slots holding an index into keys or -1."""
    bits = max(int(np.ceil(np.log2(max(2 * len(keys), 2)))), 1)
    slots = np.full(1 << bits, -1, dtype=np.int32 if len(keys) < 2 ** 31 else np.int64)
    mask = (1 << bits) - 1
    pending = np.arange(len(keys))
    at = _slot_of(keys, bits)
    while len(pending):
        where = at[pending]
        free = slots[where] == -1
        slots[where[free]] = pending[free]  # of several keys after one slot, one lands
        placed = slots[where] == pending
        pending = pending[~placed]
        at[pending] = (at[pending] + 1) & mask
    return bits, slots


def _look_up(table: tuple[int, np.ndarray], keys: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Index into ``keys`` of each query key, -1 where absent."""
    bits, slots = table
    mask = (1 << bits) - 1
    out = np.full(len(query), -1, dtype=np.int64)
    at = _slot_of(query, bits)
    todo = np.arange(len(query) if len(keys) else 0)
    while len(todo):
        index = slots[at[todo]]
        filled = index >= 0
        match = filled & (keys[np.maximum(index, 0)] == query[todo])
        out[todo[match]] = index[match]
        todo = todo[filled & ~match]
        at[todo] = (at[todo] + 1) & mask
    return out
