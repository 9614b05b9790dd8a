"""What every broad phase shares: the one-method interface, the input checks, batched pair
enumeration and the exact box-box test. The overview is in :mod:`.broadphase`.

A box is the closed interval ``[lo, hi]`` on each axis, so two boxes overlap when
``lo_i <= hi_j`` and ``lo_j <= hi_i`` on all three axes: boxes touching at a face, an edge or a
corner overlap, and a zero-size box (a point) overlaps every box containing it.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import PhysanimError
from ..transforms import column_max, column_min, row_all

AXIS_NAMES = "xyz"
# Candidate pairs handled per vectorised batch. A batch's temporaries (a dozen int64/bool arrays
# of this length, a few MB) stay in cache and are reused by the allocator: 2**16 ran a sweep over
# 1.7e8 candidates 1.6x faster than 2**21, and memory no longer grows with the candidate count.
PAIR_CHUNK = 1 << 16


@dataclass(frozen=True)
class BroadPhaseStats:
    """What one ``pairs`` call cost.

    Attributes:
        box_count: boxes given, n.
        candidate_count: box pairs given the exact box-box test (the broad phase's own cost
            measure: AllPairs tests n (n - 1) / 2).
        pair_count: overlapping pairs returned.
    """

    box_count: int
    candidate_count: int
    pair_count: int


class BroadPhase(ABC):
    """A broad phase: boxes in, overlapping index pairs out (``pairs``); swappable by design.

    Subclasses implement ``_find_pairs``; this class checks the input and puts the pairs into
    canonical form. Stateful subclasses (sweep and prune) keep what they learnt between calls
    while the box count stays the same, and start over when it changes or on ``reset()``.
    """

    def __init__(self) -> None:
        self.last_stats: BroadPhaseStats | None = None

    def pairs(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Indices of every pair of overlapping boxes (closed intervals: touching counts).

        Args:
            lo: (n, 3) lower corners [m].
            hi: (n, 3) upper corners [m], ``hi >= lo``.

        Returns:
            (m, 2) int64 array of pairs ``(i, j)`` with ``i < j``, unique and sorted
            lexicographically, so every broad phase returns the identical array.

        Raises:
            PhysanimError (a ValueError): bad shapes, a non-finite bound or ``lo > hi``, naming
                the box index and its values.
        """
        lo, hi = check_boxes(lo, hi)
        i, j, stats = self._find_pairs(lo, hi)
        self.last_stats = stats
        return canonical_pairs(i, j, len(lo))

    def reset(self) -> None:  # noqa: B027 (a hook: stateless broad phases keep nothing)
        """Forget state kept between calls (nothing for stateless broad phases)."""

    @abstractmethod
    def _find_pairs(
        self, lo: np.ndarray, hi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, BroadPhaseStats]:
        """Each overlapping pair exactly once, in any order and orientation, with the stats."""


def check_boxes(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """``lo`` and ``hi`` as (n, 3) float64 arrays; raises PhysanimError naming the bad box."""
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    if lo.ndim != 2 or lo.shape[1:] != (3,) or lo.shape != hi.shape:
        raise PhysanimError(
            f"box bounds lo and hi must both have shape (n, 3) (got {lo.shape} and {hi.shape})")
    finite = row_all(np.isfinite(lo)) & row_all(np.isfinite(hi))
    if not finite.all():
        k = int(np.argmin(finite))
        raise PhysanimError(
            f"box {k} has a non-finite bound: lo = {_fmt(lo[k])}, hi = {_fmt(hi[k])} "
            "(every box bound must be a finite number)")
    inverted = lo > hi
    if inverted.any():
        k, a = np.unravel_index(int(np.argmax(inverted)), inverted.shape)
        raise PhysanimError(
            f"box {k} is inverted along {AXIS_NAMES[a]}: lo = {float(lo[k, a])!r} > "
            f"hi = {float(hi[k, a])!r}")
    if len(lo):
        with np.errstate(over="ignore"):
            span = column_max(hi) - column_min(lo)
        if not np.isfinite(span).all():
            raise PhysanimError(
                f"the boxes span more than the float64 range (from {_fmt(lo.min(axis=0))} to "
                f"{_fmt(hi.max(axis=0))}); move them closer to the origin")
    return lo, hi


def _fmt(v: np.ndarray) -> str:
    return "(" + ", ".join(repr(float(x)) for x in v) + ")"


def canonical_pairs(i: np.ndarray, j: np.ndarray, n: int) -> np.ndarray:
    """(m, 2) int64 pairs with ``i < j``, sorted lexicographically. Input pairs must be unique."""
    i = np.asarray(i, dtype=np.int64)
    j = np.asarray(j, dtype=np.int64)
    key = np.minimum(i, j) * n + np.maximum(i, j)  # n < 3e9 keeps this inside int64
    key.sort()
    out = np.empty((len(key), 2), dtype=np.int64)
    np.floor_divide(key, n, out=out[:, 0])
    np.subtract(key, out[:, 0] * n, out=out[:, 1])
    return out


def iter_ranges(count: np.ndarray, chunk: int = PAIR_CHUNK
                ) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Every ``(source, offset)`` with ``0 <= offset < count[source]``, in batches.

    This is how the broad phases turn "source s has count[s] candidates" into flat index arrays
    without a Python loop per source: ``np.repeat`` plus one ``arange`` per batch. A batch holds
    about ``chunk`` entries (a single source with more stays whole).

    Args:
        count: (s,) non-negative int counts.
        chunk: target batch length.

    Yields:
        ``(source, offset)``, two int64 arrays of equal length.
    """
    count = np.asarray(count, dtype=np.int64)
    end = np.cumsum(count)
    total = int(end[-1]) if len(end) else 0
    first, done = 0, 0
    while done < total:
        stop = max(int(np.searchsorted(end, done + chunk, side="right")), first + 1)
        c = count[first:stop]
        last = int(end[stop - 1])
        source = np.repeat(np.arange(first, stop, dtype=np.int64), c)
        offset = np.arange(done, last, dtype=np.int64) - np.repeat(end[first:stop] - c, c)
        yield source, offset
        first, done = stop, last


def keep_overlapping(lo_t: np.ndarray, hi_t: np.ndarray, i: np.ndarray, j: np.ndarray,
                     axes: Sequence[int] = (0, 1, 2), carry: tuple[np.ndarray, ...] = ()
                     ) -> tuple[np.ndarray, ...]:
    """The pairs ``(i, j)`` whose boxes overlap (closed intervals) on every axis in ``axes``.

    Args:
        lo_t, hi_t: (3, n) transposed, contiguous box bounds (fast gathers per axis).
        i, j: (k,) int candidate pairs.
        axes: axes to test; pairs are compacted after each axis, so put the most selective first.
        carry: more (k,) arrays to compact along with the pairs.

    Returns:
        ``(i, j, *carry)`` restricted to the overlapping pairs.
    """
    kept = (i, j, *carry)
    for a in axes:
        la, ha = lo_t[a], hi_t[a]
        i, j = kept[0], kept[1]
        keep = la[i] <= ha[j]
        keep &= la[j] <= ha[i]
        where = np.flatnonzero(keep)
        kept = tuple(x[where] for x in kept)
    return kept


def transposed(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(3, n) contiguous copies of the bounds, for :func:`keep_overlapping`."""
    return np.ascontiguousarray(lo.T), np.ascontiguousarray(hi.T)


def no_pairs() -> tuple[np.ndarray, np.ndarray]:
    return np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64)


def concat_pairs(found: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    if not found:
        return no_pairs()
    return np.concatenate([f[0] for f in found]), np.concatenate([f[1] for f in found])
