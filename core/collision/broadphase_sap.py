"""Sweep and prune (the seed's "Sweep and Prune"), with temporal coherence.

Per swept axis the 2n interval endpoints (n lower, n upper) are kept in sorted order. Sweeping
the sorted list gives, for each box, how many boxes start inside its interval; those are the
boxes overlapping it on that axis. The candidates are enumerated on one swept axis and pruned
exactly on the others.

Coherence. The seed re-sorts last frame's order with insertion sort, O(n + swaps). A Python
insertion sort is far too slow and odd-even transposition passes (a vectorised insertion sort)
need as many passes as the largest displacement — hundreds at 100k boxes — so this module does
what the seed's argument relies on with numpy's own adaptive sort: it lays the new endpoint
values out in last frame's order, returns at once when they are still sorted (bodies at rest:
O(n), no sort), and otherwise sorts that nearly sorted array with ``np.argsort(kind="stable")``,
which is timsort: it merges the runs last frame's order left, about twice as fast as sorting
from scratch on the random walk of ``bench/broadphase.py``. The order found is the one insertion
sort would produce. (At those sizes enumerating candidates, not sorting, dominates a sweep.)

Swaps. ``SweepStats.displacement`` (always, O(n)) is the summed distance the endpoints moved in
the sorted list; the exact number of swaps an insertion sort would have made (the number of
inversions) satisfies ``displacement / 2 <= swaps <= displacement`` (Diaconis and Graham 1977).
With ``count_swaps=True`` the exact count is computed as well, by :func:`count_inversions`
(O(n log n), a diagnostic rather than part of the sort).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import PhysanimError
from .broadphase_base import (BroadPhase, BroadPhaseStats, concat_pairs, iter_ranges,
                              keep_overlapping, transposed)


@dataclass(frozen=True)
class SweepStats(BroadPhaseStats):
    """Stats of one sweep-and-prune call (see :class:`BroadPhaseStats` for the common fields).

    Attributes:
        sweep_axis: the swept axis (0, 1, 2 for x, y, z) whose 1-D overlaps were enumerated:
            the one with the fewest, which is ``candidate_count``.
        fresh_sort: True when the endpoints were sorted from scratch (first call, box count
            changed, or coherence off); False when last frame's order was re-sorted.
        displacement: sum over swept axes and endpoints of |new rank - old rank| (old rank: the
            previous frame's order, or the input order after a fresh sort).
        swap_count: exact insertion-sort swaps (inversions) summed over the swept axes, or None
            unless the instance counts swaps.
    """

    sweep_axis: int
    fresh_sort: bool
    displacement: int
    swap_count: int | None


class SweepAndPrune(BroadPhase):
    """Sweep and prune on 1, 2 or 3 axes, optionally coherent between calls.

    Args:
        axes: how many axes to sort: 1 sweeps x; 2 sweeps x and y; 3 sweeps x, y and z. The
            1-D overlap count of every swept axis is known in O(n) after its sort, so the
            candidates are enumerated on the swept axis with the fewest and pruned on the rest:
            more axes cost more sorting and pay off when the boxes spread unevenly.
        coherence: keep each axis's endpoint order for the next call and re-sort it (see the
            module docstring); the box count must stay the same, a new count starts afresh.
        count_swaps: also count the exact insertion-sort swaps (``SweepStats.swap_count``).

    Any box policy works; see ``cube_boxes`` (fixed-size cubes, the seed's first policy) and
    ``aabb_of_points`` / ``aabb_of_oriented_boxes`` (dynamic AABBs) in :mod:`.broadphase`.
    """

    def __init__(self, axes: int = 1, coherence: bool = True, count_swaps: bool = False):
        super().__init__()
        if axes not in (1, 2, 3) or isinstance(axes, bool):
            raise PhysanimError(f"sweep and prune axes must be 1, 2 or 3 (got {axes!r})")
        self.axes = int(axes)
        self.coherence = bool(coherence)
        self.count_swaps = bool(count_swaps)
        self._order: list[np.ndarray] | None = None  # per swept axis: (2n,) endpoint order

    def reset(self) -> None:
        self._order = None

    def _find_pairs(self, lo, hi):
        n = len(lo)
        coherent = (self.coherence and self._order is not None
                    and len(self._order[0]) == 2 * n)
        orders, displacement, swaps, sweeps = [], 0, 0, []
        for a in range(self.axes):
            values = np.concatenate([lo[:, a], hi[:, a]])
            if coherent:
                order, moved, swapped = self._resort(values, self._order[a])
            else:
                order, moved, swapped = self._sort(values)
            orders.append(order)
            displacement += moved
            swaps += swapped
            sweeps.append(_sweep(values, order, n))
        self._order = orders if self.coherence else None

        axis = int(np.argmin([count.sum() for _, count in sweeps]))
        by_lo, count = sweeps[axis]
        # bounds in rank order: a box's candidates are the next ranks, so gathers stay local
        lo_t, hi_t = transposed(lo[by_lo], hi[by_lo])
        prune = [b for b in range(3) if b != axis]
        found = []
        for rank, offset in iter_ranges(count):
            found.append(keep_overlapping(lo_t, hi_t, rank, rank + 1 + offset, prune))
        r, s = concat_pairs(found)
        i, j = by_lo[r], by_lo[s]
        stats = SweepStats(n, int(count.sum()), len(i), axis, not coherent, displacement,
                           swaps if self.count_swaps else None)
        return i, j, stats

    def _sort(self, values: np.ndarray) -> tuple[np.ndarray, int, int]:
        # stable only when counting: an unstable sort may reorder ties an insertion sort keeps
        order = np.argsort(values, kind="stable" if self.count_swaps else None)
        return order, _displacement(order), self._swaps(order)

    def _resort(self, values: np.ndarray, order: np.ndarray) -> tuple[np.ndarray, int, int]:
        laid_out = values[order]
        if not (laid_out[1:] < laid_out[:-1]).any():
            return order, 0, 0  # still sorted: nothing moved past anything
        perm = np.argsort(laid_out, kind="stable")  # timsort: merges last frame's sorted runs
        return order[perm], _displacement(perm), self._swaps(perm)

    def _swaps(self, perm: np.ndarray) -> int:
        return count_inversions(perm) if self.count_swaps else 0

    def __repr__(self) -> str:
        return (f"SweepAndPrune(axes={self.axes}, coherence={self.coherence}, "
                f"count_swaps={self.count_swaps})")


def _sweep(values: np.ndarray, order: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Sweep one axis.

    Args:
        values: (2n,) endpoint values, lower bounds then upper bounds.
        order: (2n,) indices sorting ``values``.

    Returns:
        ``by_lo``, the boxes by increasing lower bound, and ``count``: for the box at rank r of
        ``by_lo``, how many boxes of higher rank start within its interval. The boxes of ranks
        r + 1 .. r + count[r] are exactly those overlapping it on this axis that follow it, so
        every 1-D overlap is listed once.
    """
    is_lo = order < n
    by_lo = order[is_lo]
    by_hi = order[~is_lo] - n
    ordered = values[order]
    if (ordered[1:] == ordered[:-1]).any():
        # ties (touching or zero-size boxes): the sort may put an upper bound before an equal
        # lower bound, so count "lower bounds <= this upper bound" by binary search instead
        upto_sorted = np.searchsorted(values[:n][by_lo], values[n:][by_hi], side="right")
    else:
        upto_sorted = np.cumsum(is_lo)[~is_lo]  # lower bounds before each upper bound
    upto = np.empty(n, dtype=np.int64)
    upto[by_hi] = upto_sorted
    count = upto[by_lo] - np.arange(1, n + 1)
    return by_lo, count


def _displacement(perm: np.ndarray) -> int:
    return int(np.abs(perm - np.arange(len(perm))).sum())


def count_inversions(perm: np.ndarray) -> int:
    """Number of pairs ``x < y`` with ``perm[x] > perm[y]``: the swaps insertion sort makes to
    reorder a list so that new position x holds old element ``perm[x]``.

    Vectorised radix counting, O(m log m): from the highest bit down, every pair is counted at
    the highest bit where the two values differ (inverted when the one with the bit set comes
    first), then each group of equal higher bits is stably split by that bit.

    Args:
        perm: (m,) a permutation of 0 .. m - 1.
    """
    cur = np.asarray(perm, dtype=np.int64)
    m = len(cur)
    if m < 2:
        return 0
    index = np.arange(m)
    head = np.empty(m, dtype=bool)
    total = 0
    for b in range(int(m - 1).bit_length() - 1, -1, -1):
        high = cur >> (b + 1)
        bit = (cur >> b) & 1
        head[0] = True
        np.not_equal(high[1:], high[:-1], out=head[1:])
        start = np.maximum.accumulate(np.where(head, index, 0))
        ones = np.cumsum(bit) - bit  # set bits strictly before, in the whole list
        ones -= ones[start]  # ... within the element's group
        total += int(ones[bit == 0].sum())
        heads = np.flatnonzero(head)
        group = np.cumsum(head) - 1
        zeros = (np.diff(np.append(heads, m)) - np.add.reduceat(bit, heads))[group]
        position = np.where(bit == 0, index - ones, start + zeros + ones)
        nxt = np.empty_like(cur)
        nxt[position] = cur
        cur = nxt
    return total

