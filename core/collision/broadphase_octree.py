"""Octree broad phase (the seed's "Space Partition", adaptive), built level by level.

The root is the cube of side L around all boxes; level d has 2**d cells per axis. Each box gets
a level: it moves down while it is no bigger than a cell of the next level and the cell holding
its centre still has more than ``leaf_size`` boxes (so dense regions go deep, sparse ones stop
early), up to ``max_depth``. At its level a box is entered into every cell it overlaps — at most
2 per axis, 8 in all, because it is no bigger than a cell there.

Queries use a linear octree: each entry's key is its cell's Morton code padded to the deepest
level, then its level, so every cell's subtree (the cell, then all its descendants) is one
contiguous run of the sorted entries. An entry's candidates are the entries after it in its
subtree: boxes in the same cell or deeper inside it. Two overlapping boxes are both in the cells
holding the point p = max(lo_i, lo_j) at their levels, and those nest, so the pair is found from
the coarser entry (the first, at equal levels); requiring that both entries are p's cells keeps
exactly one finding.

Cell coordinates at the deepest level are ``floor((x - origin) * 2**max_depth / L)`` clipped to
the grid — non-decreasing in x — and coarser ones are bit shifts of those, so a point on a
cell face lies in one cell at every level, consistently for all boxes.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import PhysanimError
from .broadphase_base import (BroadPhase, BroadPhaseStats, concat_pairs, iter_ranges,
                              keep_overlapping, transposed)

MAX_OCTREE_DEPTH = 19  # 3 * 19 Morton bits + 5 level bits fit in an int64 sort key
_LEVEL_BITS = 5


@dataclass(frozen=True)
class OctreeStats(BroadPhaseStats):
    """Stats of one octree call (common fields in :class:`BroadPhaseStats`).

    Attributes:
        entry_count: (box, cell) entries, at most 8 per box.
        node_count: distinct cells holding an entry.
        depth: deepest level any box reached.
    """

    entry_count: int
    node_count: int
    depth: int


class Octree(BroadPhase):
    """Linear octree rebuilt on every call (stateless).

    Args:
        max_depth: deepest level, 0 .. 19 (level d has 2**d cells per axis).
        leaf_size: a cell with at most this many box centres is not split further.
    """

    def __init__(self, max_depth: int = 10, leaf_size: int = 8):
        super().__init__()
        if int(max_depth) != max_depth or not 0 <= max_depth <= MAX_OCTREE_DEPTH:
            raise PhysanimError(
                f"octree max_depth must be an integer in 0..{MAX_OCTREE_DEPTH} (got {max_depth!r})")
        if int(leaf_size) != leaf_size or leaf_size < 1:
            raise PhysanimError(f"octree leaf_size must be an integer >= 1 (got {leaf_size!r})")
        self.max_depth = int(max_depth)
        self.leaf_size = int(leaf_size)

    def _find_pairs(self, lo, hi):
        n = len(lo)
        if n < 2:
            return *concat_pairs([]), OctreeStats(n, 0, 0, 0, 0, 0)
        fine_lo, fine_hi = _fine_cells(lo, hi, self.max_depth)
        level = self._levels(fine_lo, fine_hi)
        box, shift, cell = _entries(fine_lo, fine_hi, level, self.max_depth)
        box, shift, cell, count, nodes = _linear_octree(box, shift, cell, self.max_depth)
        found = _subtree_pairs(*transposed(lo, hi), fine_lo, box, shift, cell, count)
        i, j = concat_pairs(found)
        stats = OctreeStats(n, int(count.sum()), len(i), len(box), nodes, int(level.max()))
        return i, j, stats

    def _levels(self, fine_lo: np.ndarray, fine_hi: np.ndarray) -> np.ndarray:
        """Each box's level, deciding level by level which boxes stop (vectorised per level)."""
        deep = self.max_depth
        centre = (fine_lo + fine_hi) >> 1
        level = np.full(fine_lo.shape[1], deep, dtype=np.int64)
        active = np.arange(fine_lo.shape[1])
        for d in range(deep):
            below = deep - d - 1  # shift to level d + 1
            fits_below = np.ones(len(active), dtype=bool)
            for a in range(3):
                fits_below &= (fine_hi[a, active] >> below) - (fine_lo[a, active] >> below) <= 1
            crowded = _occupancy(centre[:, active] >> (below + 1), d) > self.leaf_size
            stop = ~(fits_below & crowded)
            level[active[stop]] = d
            active = active[~stop]
            if not len(active):
                break
        return level

    def __repr__(self) -> str:
        return f"Octree(max_depth={self.max_depth}, leaf_size={self.leaf_size})"


def _fine_cells(lo: np.ndarray, hi: np.ndarray, deep: int) -> tuple[np.ndarray, np.ndarray]:
    """(3, n) int64 cell coordinates of ``lo`` and ``hi`` at the deepest level."""
    origin = lo.min(axis=0)
    side = float((hi.max(axis=0) - origin).max())
    with np.errstate(over="ignore"):
        scale = 2.0**deep / side if side > 0 else 0.0
    if not np.isfinite(scale):
        scale = 0.0  # boxes within a denormal distance: one cell holds them all
    top = 2**deep - 1
    fine_lo = np.clip(np.floor((lo - origin) * scale), 0, top).astype(np.int64).T
    fine_hi = np.clip(np.floor((hi - origin) * scale), 0, top).astype(np.int64).T
    return np.ascontiguousarray(fine_lo), np.ascontiguousarray(fine_hi)


def _occupancy(cell: np.ndarray, d: int) -> np.ndarray:
    """For each of the (3, k) level-d cells, how many of them are that same cell."""
    key = (cell[0] << 2 * d) | (cell[1] << d) | cell[2]
    if 8**d <= 4 * key.size:
        return np.bincount(key, minlength=8**d)[key]
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    return counts[inverse]


def _entries(fine_lo, fine_hi, level, deep):
    """One entry per (box, cell) a box overlaps at its level: (k,) box, (k,) shift from the
    deepest level to the entry's, (3, k) cell coordinates at the entry's level."""
    shift = deep - level
    c_lo = fine_lo >> shift
    extent = (fine_hi >> shift) - c_lo + 1  # 1 or 2 per axis
    count = extent[0] * extent[1] * extent[2]
    box = np.repeat(np.arange(len(level)), count)
    k = np.arange(len(box)) - np.repeat(np.cumsum(count) - count, count)  # index in the box
    cell = np.empty((3, len(box)), dtype=np.int64)
    for a in (2, 1, 0):  # k = (kx * ey + ky) * ez + kz
        ext = extent[a, box]
        cell[a] = c_lo[a, box] + k % ext
        k //= ext
    return box, shift[box], cell


def _linear_octree(box, shift, cell, deep):
    """Entries in linear-octree order (padded Morton code, then level), with ``count``: how
    many entries follow each one inside its cell's subtree; and the number of cells used."""
    padded = _morton(cell << shift)
    key = (padded << _LEVEL_BITS) | (deep - shift)
    order = np.argsort(key)
    key, box, shift, padded = key[order], box[order], shift[order], padded[order]
    cell = np.ascontiguousarray(cell[:, order])
    subtree_end = np.searchsorted(key, (padded + (1 << 3 * shift)) << _LEVEL_BITS)
    nodes = int(np.count_nonzero(key[1:] != key[:-1])) + 1
    return box, shift, cell, subtree_end - np.arange(1, len(key) + 1), nodes


def _subtree_pairs(lo_t, hi_t, fine_lo, box, shift, cell, count):
    """Overlapping pairs of each entry with the entries after it in its subtree, kept only when
    both entries are the cells of p = max(lo_i, lo_j) at their levels (one finding per pair)."""
    found = []
    for p, offset in iter_ranges(count):
        q = p + 1 + offset
        i, j, p, q = keep_overlapping(lo_t, hi_t, box[p], box[q], carry=(p, q))
        keep = np.ones(len(i), dtype=bool)
        for a in range(3):
            corner = np.maximum(fine_lo[a, i], fine_lo[a, j])
            keep &= (corner >> shift[p]) == cell[a, p]
            keep &= (corner >> shift[q]) == cell[a, q]
        found.append((i[keep], j[keep]))
    return found


def _morton(cell: np.ndarray) -> np.ndarray:
    """Morton (Z-order) codes of (3, k) non-negative cell coordinates below 2**21."""
    return (_spread(cell[0]) << 2) | (_spread(cell[1]) << 1) | _spread(cell[2])


def _spread(x: np.ndarray) -> np.ndarray:
    """Insert two zero bits between the bits of 21-bit integers."""
    x = x & 0x1FFFFF
    x = (x | (x << 32)) & 0x1F00000000FFFF
    x = (x | (x << 16)) & 0x1F0000FF0000FF
    x = (x | (x << 8)) & 0x100F00F00F00F00F
    x = (x | (x << 4)) & 0x10C30C30C30C30C3
    x = (x | (x << 2)) & 0x1249249249249249
    return x
