"""Uniform grid / spatial hash (the seed's "Space Partition").

Every box is entered into each cell it overlaps; boxes sharing a cell are candidates. A pair of
boxes may share several cells, so a candidate counts only in the cell holding the lower corner of
the two boxes' intersection, ``max(lo_i, lo_j)``: when the boxes overlap that point lies in both,
hence in exactly one shared cell, and the pair comes out once without a deduplication pass.

Cell coordinates are ``floor((x - origin) / cell_size)``, a non-decreasing function of x, so a
point on a cell face belongs to one cell consistently for every box; the closed-interval test
then needs no tolerance. Cells are keyed by their linear index when the grid's cell count fits
in int64, else hashed (a spatial hash; colliding cells only add candidates, which the cell check
removes).

Boxes overlapping more than ``max_cells_per_box`` cells would flood the grid; they are tested
against every box instead (a vectorised all-pairs pass over those few boxes).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import PhysanimError
from ..transforms import column_max, column_min, row_max
from .broadphase_base import (AXIS_NAMES, BroadPhase, BroadPhaseStats, concat_pairs, iter_ranges,
                              keep_overlapping, transposed)

# Automatic cell edge / mean longest box side. Two keeps a typical box in 1 to 8 cells (about
# 3.4 for equal cubes); on random scenes it beat 1, 1.5 and 3 (bench/broadphase.py scenes).
AUTO_CELL_FACTOR = 2.0
MAX_CELLS_PER_AXIS = 1 << 31  # cell coordinates stay exact and their products stay in int64
_HASH = (np.uint64(0x9E3779B97F4A7C15), np.uint64(0xC2B2AE3D27D4EB4F),
         np.uint64(0x165667B19E3779F9))  # odd 64-bit multipliers of the spatial hash


@dataclass(frozen=True)
class GridStats(BroadPhaseStats):
    """Stats of one uniform-grid call (common fields in :class:`BroadPhaseStats`).

    Attributes:
        cell_size: edge of a cell [m] (the given one, or the automatic choice).
        entry_count: (box, cell) entries in the grid.
        occupied_cell_count: distinct cells holding at least one box.
        large_box_count: boxes over ``max_cells_per_box``, tested against all boxes instead.
        hashed: True when cell keys were hashed because the grid has too many cells to number.
    """

    cell_size: float
    entry_count: int
    occupied_cell_count: int
    large_box_count: int
    hashed: bool


class UniformGrid(BroadPhase):
    """Uniform grid of cubic cells, built from scratch on every call (stateless).

    Args:
        cell_size: cell edge [m], finite and > 0; None picks ``AUTO_CELL_FACTOR`` times the
            mean over boxes of their longest side, each call.
        max_cells_per_box: boxes covering more cells than this are tested against all boxes
            rather than entered cell by cell.
        max_candidates: the candidate pairs a call may test at most (None: any number); a
            call that would test more raises :class:`TooManyCandidates` before testing any —
            boxes piled on one spot make n^2 / 2 of them, more than memory holds for a few
            hundred thousand boxes.
    """

    def __init__(self, cell_size: float | None = None, max_cells_per_box: int = 64,
                 max_candidates: int | None = None):
        super().__init__()
        self.max_candidates = max_candidates
        if cell_size is not None and not (np.isfinite(cell_size) and cell_size > 0):
            raise PhysanimError(f"grid cell_size must be finite and > 0 (got {cell_size!r})")
        if int(max_cells_per_box) != max_cells_per_box or max_cells_per_box < 1:
            raise PhysanimError(
                f"grid max_cells_per_box must be an integer >= 1 (got {max_cells_per_box!r})")
        self.cell_size = None if cell_size is None else float(cell_size)
        self.max_cells_per_box = int(max_cells_per_box)

    def _find_pairs(self, lo, hi):
        n = len(lo)
        size = self.cell_size or _auto_cell_size(lo, hi)
        if n < 2:
            return *concat_pairs([]), GridStats(n, 0, 0, size, 0, 0, 0, False)
        cell_lo, cell_hi = _cell_ranges(lo, hi, size)
        extent = cell_hi - cell_lo + 1
        large = extent.prod(axis=1, dtype=np.float64) > self.max_cells_per_box
        lo_t, hi_t = transposed(lo, hi)
        n_large = int(large.sum())
        box, cell = _entries(np.flatnonzero(~large), cell_lo, extent)
        key, hashed = _keys(cell, dims=column_max(cell_hi) + 1)
        box, cell, count, cells = _by_cell(box, cell, key)
        # each large box against every later box of [large..., small...]
        candidates = n_large * n - n_large * (n_large + 1) // 2 + int(count.sum())
        if self.max_candidates is not None and candidates > self.max_candidates:
            raise TooManyCandidates(candidates, n, self.max_candidates)
        found = _large_box_pairs(lo_t, hi_t, large)
        found += _cell_pairs(lo_t, hi_t, np.ascontiguousarray(cell_lo.T), box, cell, count,
                             hashed)
        i, j = concat_pairs(found)
        stats = GridStats(n, candidates, len(i), size, len(box), cells, int(large.sum()), hashed)
        return i, j, stats

    def __repr__(self) -> str:
        return (f"UniformGrid(cell_size={self.cell_size!r}, "
                f"max_cells_per_box={self.max_cells_per_box})")


class TooManyCandidates(PhysanimError):
    """A grid call would test more candidate pairs than its ``max_candidates``.

    Attributes: candidates, boxes, limit."""

    def __init__(self, candidates: int, boxes: int, limit: int):
        self.candidates, self.boxes, self.limit = candidates, boxes, limit
        super().__init__(f"{candidates:,} candidate pairs among {boxes:,} boxes (at most "
                         f"{limit:,} allowed)")


def _auto_cell_size(lo: np.ndarray, hi: np.ndarray) -> float:
    """``AUTO_CELL_FACTOR`` x the median longest box side (robust to a few huge boxes, which
    go to the large-box pass), at least 2**-20 of the scene; for points, ~one point per cell."""
    if len(lo) == 0:
        return 1.0
    span = float((column_max(hi) - column_min(lo)).max())
    size = AUTO_CELL_FACTOR * float(np.median(row_max(hi - lo)))
    if size == 0:
        size = span / np.cbrt(len(lo))
    return float(max(size, span / 2**20)) if span > 0 else 1.0


def _cell_ranges(lo: np.ndarray, hi: np.ndarray, size: float) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) int64 first and last cell of every box along each axis."""
    origin = column_min(lo)
    with np.errstate(over="ignore"):  # an overflow to inf is caught just below
        cell_lo = np.floor((lo - origin) / size)
        cell_hi = np.floor((hi - origin) / size)
    if cell_hi.max() >= MAX_CELLS_PER_AXIS:
        a = int(np.argmax(cell_hi.max(axis=0)))
        raise PhysanimError(
            f"grid cell_size {size!r} m is too small for boxes spanning "
            f"{float(hi[:, a].max() - origin[a])!r} m along {AXIS_NAMES[a]} "
            f"(more than 2**31 cells); use a larger cell_size")
    return cell_lo.astype(np.int64), cell_hi.astype(np.int64)


def _by_cell(box, cell, key):
    """Entries sorted by cell key; ``count``: entries after each one in its cell."""
    order = np.argsort(key)
    key, box, cell = key[order], box[order], np.ascontiguousarray(cell[:, order])
    head = np.empty(len(key), dtype=bool)
    head[:1] = True
    np.not_equal(key[1:], key[:-1], out=head[1:])
    heads = np.flatnonzero(head)
    group_end = np.append(heads[1:], len(key))[np.cumsum(head) - 1]
    return box, cell, group_end - np.arange(1, len(key) + 1), len(heads)


def _cell_pairs(lo_t, hi_t, cell_lo_t, box, cell, count, hashed):
    """Overlapping pairs among entries sharing a cell, each from the cell of max(lo_i, lo_j)."""
    found = []
    for p, offset in iter_ranges(count):
        q = p + 1 + offset
        i, j, p, q = keep_overlapping(lo_t, hi_t, box[p], box[q], carry=(p, q))
        keep = np.ones(len(i), dtype=bool)
        for a in range(3):
            keep &= np.maximum(cell_lo_t[a, i], cell_lo_t[a, j]) == cell[a, p]
            if hashed:  # one hash bucket may hold several cells
                keep &= cell[a, q] == cell[a, p]
        found.append((i[keep], j[keep]))
    return found


def _entries(boxes, cell_lo, extent):
    """One (box, cell) entry per cell each box overlaps: (k,) boxes and (3, k) cells."""
    mine = np.take(extent, boxes, axis=0)
    count = mine[:, 0] * mine[:, 1] * mine[:, 2]  # (a reduction along 3 is slow in numpy)
    if (count == 1).all():  # one cell each (small boxes): their first cells
        return boxes, np.ascontiguousarray(np.take(cell_lo, boxes, axis=0).T)
    box = np.repeat(boxes, count)
    k = np.arange(len(box)) - np.repeat(np.cumsum(count) - count, count)  # index in the box
    ext, first = np.take(extent, box, axis=0), np.take(cell_lo, box, axis=0)  # rows: fast
    ey, ez = ext[:, 1], ext[:, 2]
    cell = np.empty((3, len(box)), dtype=np.int64)
    cell[2] = first[:, 2] + k % ez
    k //= ez
    cell[1] = first[:, 1] + k % ey
    cell[0] = first[:, 0] + k // ey
    return box, cell


def _keys(cell, dims):
    """Cell keys: the linear cell index when the grid is small enough, else a 64-bit hash."""
    dx, dy, dz = (int(d) for d in dims)
    if dx * dy * dz < 1 << 62:
        return (cell[0] * dy + cell[1]) * dz + cell[2], False
    u = cell.astype(np.uint64)
    return (u[0] * _HASH[0]) ^ (u[1] * _HASH[1]) ^ (u[2] * _HASH[2]), True


def _large_box_pairs(lo_t, hi_t, large):
    """Pairs involving the large boxes: each against every later box of [large..., small...]."""
    if not large.any():
        return []
    order = np.concatenate([np.flatnonzero(large), np.flatnonzero(~large)])
    n_large, n = int(large.sum()), len(order)
    count = n - np.arange(1, n_large + 1)
    found = []
    for r, offset in iter_ranges(count):
        found.append(keep_overlapping(lo_t, hi_t, order[r], order[r + 1 + offset]))
    return found
