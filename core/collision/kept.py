"""Candidate pairs and continuous tests kept between detections: a spring mesh detects its
pairs many times per sub-step (each separating round, each landing round), with its boxes and
points barely moved between them; both keep what still holds and find again only the rest,
and both give exactly what a fresh search or test gives (the tests: for every pair not shown
apart by the caller's bound; of those, which are near is still exact)."""
from __future__ import annotations

import numpy as np

from ..transforms import row_any
from .crossing import Separation, box_pairs

# a search in which more than this fraction of the boxes left their grown ones starts afresh
# (a partial one finds the pairs of those boxes only, and merges them into the kept ones)
PARTIAL = 0.25
FEW_TIMES_ALL = 1 << 21  # box pairs a partial search tries one by one (else by the search)


class KeptPairs:
    """Box pairs kept between searches (a Verlet list): a search from boxes that moved little
    since the last one reads the pairs it found then instead of searching again.

    Each box's pairs are found for its box grown by ``margin``; the kept pairs hold every
    overlapping pair of later boxes that each still lie within their grown box. A box that
    left its grown box is grown again where it is now and only its pairs are searched again
    (against every other box's grown box, which holds that box: the same superset), merged in
    order into the others'; when more than PARTIAL of the boxes left, or their count changed,
    everything is searched again. A search keeps the kept pairs overlapping now: exactly what a
    fresh search gives, in the same order (by the first index, then the second). Nothing is
    kept when pickled (a resumed bake searches afresh).

    Args:
        find: the search, ``find(lo_a, hi_a, lo_b, hi_b) -> (i, j)`` (default
            :func:`~.crossing.box_pairs`), or, for ``within=True``, ``find(lo, hi) -> (i, j)``:
            the pairs (i < j) among one set of boxes; both sorted by i, then j.
        across: the search across two sets a partial search uses for a set of one
            (``within=True``; default :func:`~.crossing.box_pairs`).
        exclude: ``exclude(i, j) -> (c,) bool``, the pairs never wanted (e.g. a mesh's
            elements that share a vertex: neighbours' boxes always overlap, and they were
            most of a cloth's candidates), dropped as they are found: the pairs are a fresh
            search's without them. None: none.
    """

    def __init__(self, find=None, within: bool = False, across=None, exclude=None):
        self.find = box_pairs if find is None else find
        self.within = within
        self.across = box_pairs if across is None else across
        self.exclude = exclude
        self._grown: tuple[np.ndarray, ...] | None = None
        self._pairs: tuple[np.ndarray, np.ndarray] | None = None
        self.searches = [0, 0]  # (whole, partial) searches made: for benchmarks and tests

    def __getstate__(self):
        return {"find": self.find, "within": self.within, "across": self.across,
                "exclude": self.exclude, "_grown": None, "_pairs": None, "searches": [0, 0]}

    def __setstate__(self, state: dict) -> None:
        # (a checkpoint written before partial searches has none of the first three)
        self.__dict__.update({"across": box_pairs, "searches": [0, 0], "exclude": None,
                              **state})

    def pairs(self, margin: float, lo_a: np.ndarray, hi_a: np.ndarray,
              lo_b: np.ndarray | None = None, hi_b: np.ndarray | None = None,
              only: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The overlapping pairs (i into A, j into B; within one set: i < j) of these boxes,
        (n, 3) each; B is A for a search within one set. ``only`` (bool over A's boxes, a
        search within one set): just the pairs with at least one of them (the same pairs as
        filtering the result, tested fewer)."""
        boxes = (lo_a, hi_a) if self.within else (lo_a, hi_a, lo_b, hi_b)
        try:
            self._update(margin, boxes)
        except BaseException:  # (a refused search: nothing half-updated is kept)
            self._grown = self._pairs = None
            raise
        i, j = self._pairs
        if only is not None and self.within:
            keep = np.flatnonzero(only[i] | only[j])
            i, j = i[keep], j[keep]
        return _overlapping(lo_a, hi_a, *boxes[-2:], i, j)

    def _update(self, margin: float, boxes: tuple[np.ndarray, ...]) -> None:
        """The kept pairs made to hold for ``boxes``: as they were, partly or wholly searched
        again."""
        grown = self._grown
        if grown is None or any(b.shape != g.shape for b, g in zip(boxes, grown)):
            self._search(margin, boxes)
            return
        # (a box with a NaN has left: the whole search refuses it, naming it)
        left = [row_any(~(boxes[k] >= grown[k])) | row_any(~(boxes[k + 1] <= grown[k + 1]))
                for k in range(0, len(boxes), 2)]
        count = sum(int(x.sum()) for x in left)
        if not count:
            return
        if count > PARTIAL * sum(len(x) for x in left) or not all(
                np.isfinite(b[left[k // 2]]).all() for k, b in enumerate(boxes)):
            self._search(margin, boxes)
            return
        self.searches[1] += 1
        for k, b in enumerate(boxes):  # the boxes that left: grown again where they are
            rows = left[k // 2]
            grown[k][rows] = b[rows] + (margin if k % 2 else -margin)
        i, j = self._pairs
        if self.within:
            out, = left
            stay = ~(out[i] | out[j])
            new_i, new_j = self._within_of(np.flatnonzero(out), out)
            n = len(out)
        else:
            out_a, out_b = left
            stay = ~(out_a[i] | out_b[j])
            new_i, new_j = self._across_of(np.flatnonzero(out_a), np.flatnonzero(out_b))
            n = len(out_b)
        self._pairs = _merged(i[stay], j[stay], *self._wanted(new_i, new_j), n)

    def _search(self, margin: float, boxes: tuple[np.ndarray, ...]) -> None:
        self.searches[0] += 1
        self._grown = tuple(b + (margin if k % 2 else -margin) for k, b in enumerate(boxes))
        self._pairs = self._wanted(*self.find(*self._grown))

    def _wanted(self, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.exclude is None or not len(i):
            return i, j
        keep = np.flatnonzero(~self.exclude(i, j))
        return i[keep], j[keep]

    def _within_of(self, moved: np.ndarray, out: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The grown pairs (i < j) of the boxes ``moved`` (indices; ``out`` the same as a mask)
        with every box: each found from a moved box's side, a pair of two moved boxes once."""
        lo, hi = self._grown
        x, y = _few_with_all(lo[moved], hi[moved], lo, hi, self.across)
        a = moved[x]
        keep = (a != y) & (~out[y] | (a < y))
        a, y = a[keep], y[keep]
        return np.minimum(a, y), np.maximum(a, y)

    def _across_of(self, moved_a: np.ndarray, moved_b: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
        """The grown pairs of A's boxes ``moved_a`` with all of B's, and of A's others with
        B's boxes ``moved_b``."""
        lo_a, hi_a, lo_b, hi_b = self._grown
        i, j = [], []
        if len(moved_a):
            x, y = _few_with_all(lo_a[moved_a], hi_a[moved_a], lo_b, hi_b, self.find)
            i.append(moved_a[x])
            j.append(y)
        if len(moved_b):
            rest = np.ones(len(lo_a), bool)
            rest[moved_a] = False
            rest = np.flatnonzero(rest)
            y, x = _few_with_all(lo_b[moved_b], hi_b[moved_b], lo_a[rest], hi_a[rest],
                                 self.find)
            i.append(rest[x])
            j.append(moved_b[y])
        return np.concatenate(i), np.concatenate(j)


def _few_with_all(lo_f: np.ndarray, hi_f: np.ndarray, lo: np.ndarray, hi: np.ndarray, search
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The overlapping pairs (f, j) of a few boxes with all (``search`` when they are not
    few), in any order: each few box against the boxes whose x-range can meet its own — all
    boxes sorted by their low x, a few box's candidates are those starting between its low x
    less the widest box and its high x, one slice of that order — then axis by axis, the
    candidates compacted after each (a grid over all the boxes costs several times more for a
    few). Where the slices hold more than a quarter of all the pairs, every pair is tried."""
    if len(lo_f) * len(lo) > FEW_TIMES_ALL:
        return search(lo_f, hi_f, lo, hi)
    if len(lo) and len(lo_f):
        order = np.argsort(lo[:, 0], kind="stable")
        start = lo[order, 0]
        width = float(np.max(hi[:, 0] - lo[:, 0]))
        first = np.searchsorted(start, lo_f[:, 0] - width, side="left")
        count = np.searchsorted(start, hi_f[:, 0], side="right") - first
        np.maximum(count, 0, out=count)
        total = int(count.sum())
        if 4 * total <= len(lo_f) * len(lo):
            f = np.repeat(np.arange(len(lo_f)), count)
            j = order[np.repeat(first - np.cumsum(count) + count, count) + np.arange(total)]
            return _overlapping(lo_f, hi_f, lo, hi, f, j)
    f, j = np.nonzero((lo_f[:, None, 0] <= hi[None, :, 0]) & (lo[None, :, 0] <= hi_f[:, None, 0]))
    return _overlapping(lo_f, hi_f, lo, hi, f, j, axes=(1, 2))


def _overlapping(lo_a, hi_a, lo_b, hi_b, i: np.ndarray, j: np.ndarray, axes=(0, 1, 2)
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The pairs (i into A's boxes, j into B's) that overlap on every axis of ``axes``, axis by
    axis, compacted after each (1-D gathers)."""
    for a in axes:
        if not len(i):
            break
        keep = np.flatnonzero((lo_a[:, a][i] <= hi_b[:, a][j]) & (lo_b[:, a][j] <= hi_a[:, a][i]))
        i, j = i[keep], j[keep]
    return i, j


def _merged(i: np.ndarray, j: np.ndarray, new_i: np.ndarray, new_j: np.ndarray, n: int
            ) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i, j) sorted by i then j (j < n) with the new pairs (any order, none of them
    among the first) put in their places."""
    key = new_i * n + new_j
    order = np.argsort(key, kind="stable")
    at = np.searchsorted(i * n + j, key[order])
    return np.insert(i, at, new_i[order]), np.insert(j, at, new_j[order])


class KeptTests:
    """The continuous tests of the last detection, kept for the next: a sub-step detects again
    after each round of separating pushes, which move a few of the points, and a pair none of
    whose points (or features) moved since gives the same :class:`Separation`. Only the other
    pairs are tested again; each pair's test reads its own points only, so the result is a
    fresh detection's to the bit — except for the pairs a caller's ``apart`` shows too far
    apart to matter (:meth:`separations`), which keep a lower bound of their gap and their
    last weights and normal instead of a test (which pairs are near or crossed is still a
    fresh detection's). Nothing is kept when pickled.

    A detection calls :meth:`begin` with its inputs, then :meth:`separations` per kind of
    pair; a kind the last detection did not test is tested afresh."""

    def __init__(self):
        self._inputs: tuple = ()
        self._kept: dict[str, tuple[int, np.ndarray, Separation]] = {}
        self._detection = 0

    def __getstate__(self):
        return {"_inputs": (), "_kept": {}, "_detection": 0}

    def begin(self, *groups: tuple[np.ndarray, ...]) -> list[np.ndarray]:
        """A detection from these inputs: per group of arrays (each (n, ...), n the group's
        count of points or features), (n,) bool: the rows that differ from the last
        detection's (every row when there was none, or another shape)."""
        last = self._inputs
        out = []
        for k, arrays in enumerate(groups):
            n = len(arrays[0])
            before = last[k] if len(last) == len(groups) else None
            if not n:
                out.append(np.zeros(0, bool))
                continue
            if before is None or any(a.shape != b.shape for a, b in zip(arrays, before)):
                out.append(np.ones(n, bool))
                continue
            moved = np.zeros(n, bool)
            for a, b in zip(arrays, before):
                moved |= row_any((a != b).reshape(n, -1))
            out.append(moved)
        self._inputs = tuple(tuple(a.copy() for a in arrays) for arrays in groups)
        self._detection += 1
        return out

    def separations(self, kind: str, keys: np.ndarray, stale: np.ndarray, test,
                    apart=None) -> Separation:
        """The separations of the pairs ``keys`` (c,) (int64, one per pair of this ``kind``):
        the last detection's for pairs not ``stale`` (c,) (none of their points or features
        moved since) that it tested, ``test(rows)`` (rows: indices into keys) for the
        others. ``apart(rows, gap) -> (far, bound)``: for the stale pairs the last detection
        knew (``rows``, their last ``gap`` (r,)), which are shown apart without a test
        (``far`` (r,) bool: their points moved too little since to have come near or met)
        and a lower bound of their gap now (r,); those keep their last separation with that
        bound as its gap, and are not tested (their ``crossed`` is False)."""
        last = self._kept.get(kind)
        reuse = np.zeros(len(keys), bool)
        skipped, bound = np.zeros(0, np.int64), None
        if last is not None and last[0] == self._detection - 1 and len(last[1]) and len(keys):
            at = np.minimum(np.searchsorted(last[1], keys), len(last[1]) - 1)
            known = last[1][at] == keys
            reuse = ~stale & known
            if apart is not None:
                rows = np.flatnonzero(stale & known)
                if len(rows):
                    far, bound = apart(rows, last[2].gap[at[rows]])
                    skipped, bound = rows[far], bound[far]
                    reuse[skipped] = True
        fresh = np.flatnonzero(~reuse)
        if len(fresh) == len(keys):
            out = test(fresh)
        else:
            new = test(fresh) if len(fresh) else None
            kept = np.flatnonzero(reuse)  # (indices: each field's assignment reads them once)
            old = at[kept]

            def merged(field):
                before = getattr(last[2], field)
                out = np.empty((len(keys),) + before.shape[1:], before.dtype)
                out[kept] = before[old]
                if new is not None:
                    out[fresh] = getattr(new, field)
                return out

            out = Separation(*(merged(f) for f in Separation._fields))
            if len(skipped):
                out.gap[skipped] = bound
                out.crossed[skipped] = False
        if np.all(keys[1:] > keys[:-1]):
            self._kept[kind] = (self._detection, keys, out)
        else:
            order = np.argsort(keys, kind="stable")
            self._kept[kind] = (self._detection, keys[order],
                                Separation(*(x[order] for x in out)))
        return out
