"""Fixed-radius neighbours of points: a uniform cell grid (cell list) with cells as wide as the
radius, so every pair closer than it lies in the same or adjacent cells.

Points are sorted by cell; each occupied cell meets itself and 13 of its 26 neighbours (one of
each opposite pair: the half shell), so a pair of cells is visited once and a pair of points
comes out once, with i < j in the sorted order. The cell pairs are taken a few offsets at a
time (the candidate arrays stay bounded); those of like sizes meet side by side in dense
blocks, each cell's points against the other's (padded to the block's largest), and a pair is
kept when its points are within the radius; a cell pair too big for a batch alone (a crowded
cell) is taken a few rows at a time.

Cell keys are linear cell indices when the grid's cell count fits in int64, else a 64-bit hash
of the cell coordinates (two cells sharing a hash only add candidates, which the distance test
removes; the neighbour cell's key is hashed the same way, so nothing is missed).
"""
from __future__ import annotations

import numpy as np

from .broadphase_grid import _HASH

#: the half shell: (0, 0, 0) and one offset of each opposite pair of the 26 neighbours
HALF_SHELL = np.array([(0, 0, 0)] + [(dx, dy, dz) for dx in (-1, 0, 1) for dy in (-1, 0, 1)
                                     for dz in (-1, 0, 1) if (dx, dy, dz) > (0, 0, 0)],
                      dtype=np.int64)
#: candidate pairs held at once (a few arrays of them; a single cell pair above it is taken a
#: few rows at a time)
BATCH = 4_000_000
#: candidates of one dense block of cell pairs (:meth:`PointGrid._dense`), padding included (a
#: single cell pair bigger than this, up to BATCH, is a block alone)
BLOCK = 1 << 15
#: squared distances within this relative margin of the radius's are tested again as a pair
#: of points' own (:func:`_within`): a sum of three squares rounds by its order
MARGIN = 8.0 * np.finfo(np.float64).eps
#: candidate pairs one search may test (a minute or so of numpy): beyond, points are crowded
#: within the radius and the search would be all pairs of them
MAX_CANDIDATES = 500_000_000


class PointGrid:
    """The cells of points ``x`` (n, 3) [m] for neighbour queries within ``radius`` [m] (> 0).

    Attributes:
        order: (n,) the points sorted by cell. cell_start, cell_count: (c,) each occupied
            cell's run in ``order``. cell: (c, 3) its coordinates. key: (c,) its sorted keys.
    """

    def __init__(self, x: np.ndarray, radius: float):
        x = np.asarray(x, dtype=np.float64).reshape(-1, 3)
        if not (np.isfinite(radius) and radius > 0.0):
            raise ValueError(f"neighbour radius must be finite and > 0 (got {radius})")
        if not np.isfinite(x).all():
            raise ValueError("neighbour search: a point is not finite")
        self.x, self.radius = x, float(radius)
        if not len(x):
            self.order = np.zeros(0, np.int64)
            self.cell = np.zeros((0, 3), np.int64)
            self.key = self.cell_start = self.cell_count = np.zeros(0, np.int64)
            return
        lo = x.min(axis=0)
        coords = np.floor((x - lo) / self.radius).astype(np.int64)
        self._dims = coords.max(axis=0) + 3  # room for the -1 / +1 neighbours
        coords += 1
        keys = self._key(coords)
        self.order = np.argsort(keys, kind="stable")
        sorted_keys = keys[self.order]
        starts = np.concatenate([[0], np.flatnonzero(np.diff(sorted_keys)) + 1])
        self.key = sorted_keys[starts]
        self.cell_start = starts
        self.cell_count = np.diff(np.concatenate([starts, [len(x)]]))
        self.cell = coords[self.order[starts]]

    def _key(self, cell: np.ndarray) -> np.ndarray:
        dx, dy, dz = (int(d) for d in self._dims)
        if dx * dy * dz < 1 << 62:
            return (cell[:, 0] * dy + cell[:, 1]) * dz + cell[:, 2]
        u = cell.astype(np.uint64)
        return ((u[:, 0] * _HASH[0]) ^ (u[:, 1] * _HASH[1]) ^ (u[:, 2] * _HASH[2])).view(np.int64)

    def candidate_count(self) -> int:
        """Point pairs the search will test: the pairs within each cell and with its half
        shell (what :meth:`pairs` costs)."""
        if not len(self.key):
            return 0
        total = 0
        for a, b in self._cell_pairs():
            block = self.cell_count[a] * self.cell_count[b]
            total += int(np.where(a == b, (block - self.cell_count[a]) // 2, block).sum())
        return total

    def pairs(self, limit: int = MAX_CANDIDATES) -> tuple[np.ndarray, np.ndarray]:
        """Every pair of points within the radius (Euclidean, inclusive), once: (i, j), (k,)
        each, original indices.

        Raises:
            ValueError: more than ``limit`` candidate pairs (points crowded within the radius:
                the search would be all pairs of them), with their number.
        """
        if not len(self.key):
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        count = self.candidate_count()
        if count > limit:
            raise ValueError(f"{count:,} point pairs lie within {self.radius:g} m of each other "
                             f"(at most {limit:,} are searched)")
        out_i, out_j = [], []
        # the candidates as places in the cell order (each cell's points side by side: the
        # positions read are near each other in memory), back to the points' own indices only
        # for the pairs kept
        xs = np.ascontiguousarray(self.x[self.order].T)  # (3, n): by component
        for a, b in self._cell_pairs():
            big = self.cell_count[a] * self.cell_count[b] > BATCH
            for i, j in (self._dense(xs, a[~big], b[~big]), self._crowded(xs, a[big], b[big])):
                out_i.append(self.order[i])
                out_j.append(self.order[j])
        if not out_i:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        return np.concatenate(out_i), np.concatenate(out_j)

    def _dense(self, xs: np.ndarray, a: np.ndarray, b: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
        """The pairs within the radius of the cell pairs (a, b), as places in the cell order:
        cell pairs of like sizes side by side in dense blocks (each cell's points against the
        other's, padded to the block's largest; about BLOCK candidates a block), so a candidate
        costs no index arithmetic of its own; within one cell (a == b) each pair once. In the
        order of the cell pairs given, each one's row by row (the order the forces sum the
        pairs in: a sum's rounding follows it)."""
        out_i, out_j = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
        if not len(a):
            return out_i[0], out_j[0]
        keys = [np.zeros(0, np.int64)]
        width = int(self.cell_count[np.concatenate([a, b])].max())
        ca, cb = self.cell_count[a], self.cell_count[b]
        order = np.lexsort((cb, ca))
        ca, cb, sa, sb = ca[order], cb[order], self.cell_start[a[order]], \
            self.cell_start[b[order]]
        same = (a == b)[order]
        last = len(xs[0]) - 1
        r2 = self.radius * self.radius
        lo = 0
        while lo < len(ca):
            pa = int(ca[lo])
            run = int(np.searchsorted(ca, pa, side="right"))  # (this many points on side a)
            run = min(run, lo + max(1, BLOCK // pa))  # (no block takes more of them)
            grow = np.maximum.accumulate(cb[lo:run])
            fits = np.arange(1, run - lo + 1) * pa * grow <= BLOCK
            hi = lo + max(1, int(np.count_nonzero(fits)))
            pb = int(grow[hi - lo - 1])
            rows = sa[lo:hi, None] + np.arange(pa)  # (g, pa): every row real (sizes sorted)
            cols = sb[lo:hi, None] + np.arange(pb)
            real = np.arange(pb) < cb[lo:hi, None]
            cols = np.minimum(cols, last)
            dist = np.zeros((hi - lo, pa, pb))
            for k in range(3):
                d = xs[k][rows][:, :, None] - xs[k][cols][:, None, :]
                dist += d * d
            near = (dist <= r2 * (1.0 + MARGIN)) & real[:, None, :]
            if same[lo:hi].any():  # a cell with itself: each pair once
                near &= ~same[lo:hi, None, None] | (np.arange(pa)[:, None] < np.arange(pb))
            g, p, q = np.nonzero(near)
            edge = np.flatnonzero(dist[g, p, q] > r2 * (1.0 - MARGIN))
            if len(edge):  # at the radius: as a pair's own test rounds it
                keep = np.ones(len(g), bool)
                keep[edge] = _within(xs, rows[g[edge], p[edge]], cols[g[edge], q[edge]], r2)
                g, p, q = g[keep], p[keep], q[keep]
            out_i.append(rows[g, p])
            out_j.append(cols[g, q])
            keys.append((order[lo + g] * width + p) * width + q)
            lo = hi
        back = np.argsort(np.concatenate(keys), kind="stable")
        return np.concatenate(out_i)[back], np.concatenate(out_j)[back]

    def _crowded(self, xs: np.ndarray, a: np.ndarray, b: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        """The pairs within the radius of cell pairs bigger than BATCH alone (a crowded cell),
        a few of their rows at a time, as places in the cell order."""
        out_i, out_j = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
        for ca, cb in zip(a.tolist(), b.tolist()):
            rows = max(1, BATCH // int(self.cell_count[cb]))
            for r0 in range(0, int(self.cell_count[ca]), rows):
                i, j = self._expand_rows(ca, cb, r0, min(r0 + rows, int(self.cell_count[ca])))
                near = _within(xs, i, j, self.radius * self.radius)
                out_i.append(i[near])
                out_j.append(j[near])
        return np.concatenate(out_i), np.concatenate(out_j)

    def _cell_pairs(self):
        """(cell a, cell b) index arrays per batch: a with itself and its half-shell
        neighbours that are occupied."""
        batch_a, batch_b, size = [], [], 0
        for offset in HALF_SHELL:
            if not offset.any():
                a = np.arange(len(self.key))
                b = a
            else:
                wanted = self._key(self.cell + offset)
                b = np.searchsorted(self.key, wanted)
                b = np.minimum(b, len(self.key) - 1)
                hit = self.key[b] == wanted
                a, b = np.flatnonzero(hit), b[hit]
                if self._hashed:  # a hash may name the cell itself: that block came already
                    keep = a != b
                    a, b = a[keep], b[keep]
            work = int((self.cell_count[a] * self.cell_count[b]).sum())
            if size and size + work > BATCH:
                yield np.concatenate(batch_a), np.concatenate(batch_b)
                batch_a, batch_b, size = [], [], 0
            batch_a.append(a)
            batch_b.append(b)
            size += work
        if batch_a:
            yield np.concatenate(batch_a), np.concatenate(batch_b)

    @property
    def _hashed(self) -> bool:
        dx, dy, dz = (int(d) for d in self._dims)
        return dx * dy * dz >= 1 << 62

    def _expand_rows(self, a: int, b: int, r0: int, r1: int) -> tuple[np.ndarray, np.ndarray]:
        """The point pairs of rows r0..r1 of cell a against cell b (a == b: each pair once), as
        places in the cell order."""
        p = np.repeat(np.arange(r0, r1), self.cell_count[b])
        q = np.tile(np.arange(self.cell_count[b]), r1 - r0)
        if a == b:
            keep = p < q
            p, q = p[keep], q[keep]
        return self.cell_start[a] + p, self.cell_start[b] + q


def _within(xs: np.ndarray, i: np.ndarray, j: np.ndarray, r2: float) -> np.ndarray:
    """(m,) whether the points at places i and j (of ``xs``, (3, n) by component) lie within
    the radius (squared ``r2``), each pair's squared distance summed as a row's own (einsum
    over its three differences), as every caller has always had it: which pairs at the radius
    are in does not change with how the search is laid out."""
    d = np.stack([xs[k][i] - xs[k][j] for k in range(3)], axis=1)
    return np.einsum("ij,ij->i", d, d) <= r2


def neighbour_pairs(x: np.ndarray, radius: float,
                    limit: int = MAX_CANDIDATES) -> tuple[np.ndarray, np.ndarray]:
    """Every pair of points of ``x`` (n, 3) within ``radius``, once: (i, j) index arrays
    (ValueError beyond ``limit`` candidate pairs, see :meth:`PointGrid.pairs`)."""
    return PointGrid(x, radius).pairs(limit)
