"""Assembled block-sparse matrices for the implicit spring-mesh solve.

A spring mesh's implicit system couples a vertex only with the few vertices its springs and
hinges reach, so the matrix is a set of 3 x 3 blocks on a fixed pattern: the diagonal plus every
pair of vertices that share a spring or a hinge. The pattern depends on the topology only and is
built once, together with, for every stored block, the list of force terms that add to it. Each
linearisation then fills the blocks by gathering those terms and summing them (no scatter),
and every conjugate-gradient product is one gather and one batched matrix product over padded
rows (ELLPACK layout) — about three times faster in numpy than applying each force's Jacobian
matrix-free, and the diagonal blocks the preconditioner needs come for free. The matrix is
symmetric: only blocks with row vertex <= column vertex are filled, then mirrored.
"""
from __future__ import annotations

import numpy as np

BLOCK = np.arange(9)


class BlockPattern:
    """Which 3 x 3 blocks of a symmetric n-vertex matrix may be non-zero.

    Args:
        n: vertex count.
        cliques: (m, k) vertex-index arrays (k >= 2); every ordered pair of vertices within a row
            couples (pairs of a spring: k = 2; the four vertices of a hinge: k = 4).

    Each matrix row stores ``width`` blocks (the largest vertex degree + 1); shorter rows are
    padded with zero blocks that point at the row's own vertex.
    """

    def __init__(self, n: int, cliques):
        self.n = int(n)
        rows, cols = [np.arange(self.n)], [np.arange(self.n)]
        for clique in cliques:
            clique = np.asarray(clique, dtype=np.int64)
            for a in range(clique.shape[1]):
                for b in range(clique.shape[1]):
                    if a != b:
                        rows.append(clique[:, a])
                        cols.append(clique[:, b])
        key = np.unique(np.concatenate(rows) * self.n + np.concatenate(cols))
        row, col = key // self.n, key % self.n
        degree = np.bincount(row, minlength=self.n)
        self.width = int(degree.max())
        start = np.concatenate([[0], np.cumsum(degree)[:-1]])
        column = np.arange(len(key)) - start[row]  # position of the block within its row
        self.neighbours = np.repeat(np.arange(self.n)[:, None], self.width, axis=1)
        self.neighbours[row, column] = col
        self._key = key
        self._slot = row * self.width + column
        self.diagonal_slot = self._slot[np.searchsorted(key, np.arange(self.n) * (self.n + 1))]
        self._tables: dict = {}
        self._scratch: dict = {}
        # mirror map: block (c, r) = block (r, c)^T for every stored r < c
        upper = row < col
        mirror = np.searchsorted(key, col[upper] * self.n + row[upper])
        self._upper = self.flat_positions(self._slot[upper]).ravel()
        self._lower = self.flat_positions(self._slot[mirror])[:, (BLOCK % 3) * 3 + BLOCK // 3].ravel()

    def scratch(self, key, shape) -> np.ndarray:
        """A reusable work array of ``shape`` (float64) kept with the pattern."""
        buffer = self._scratch.get(key)
        if buffer is None or buffer.shape != tuple(shape):
            buffer = self._scratch[key] = np.empty(shape)
        return buffer

    @property
    def size(self) -> int:
        """Number of stored values: n rows x 3 x (width x 3)."""
        return self.n * 9 * self.width

    def flat_positions(self, slots: np.ndarray) -> np.ndarray:
        """Flat indices into the (n, 3, width * 3) value array of each 3 x 3 block at ``slots``
        (row * width + column), component order (a, b) row-major: shape slots.shape + (9,)."""
        slots = np.asarray(slots, dtype=np.int64)
        row, column = slots // self.width, slots % self.width
        a, b = BLOCK // 3, BLOCK % 3
        base = row * (9 * self.width) + column * 3
        return base[..., None] + a * (3 * self.width) + b

    def _groups(self, clique: np.ndarray) -> list:
        """For every stored block (row vertex <= column vertex) a clique adds to: which of its
        entries (row, a, b) add there, bucketed by how many do (so no table is padded).
        Returns [(positions (S, 9), entry a (S, M), entry b (S, M))] with entries as flat
        indices row * k + a into the clique's (m, k) members. Cached on the array's identity
        (cliques are the model's fixed index arrays)."""
        hit = self._tables.get(id(clique))
        if hit is not None and hit[0] is clique:
            return hit[1]
        c = np.asarray(clique, dtype=np.int64)
        m, k = c.shape
        mm, a, b = (g.ravel() for g in np.meshgrid(np.arange(m), np.arange(k), np.arange(k),
                                                    indexing="ij"))
        r, col = c[mm, a], c[mm, b]
        keep = r <= col
        ea, eb, r, col = (mm * k + a)[keep], (mm * k + b)[keep], r[keep], col[keep]
        key = r * self.n + col
        found = np.searchsorted(self._key, key)
        if np.any(self._key[np.minimum(found, len(self._key) - 1)] != key):
            raise ValueError("the clique couples vertices outside the block pattern")
        slot = self._slot[found]
        order = np.argsort(slot, kind="stable")
        slots, start, count = np.unique(slot[order], return_index=True, return_counts=True)
        groups = []
        for width in np.unique(count).tolist():
            chosen = count == width
            rows = (start[chosen][:, None] + np.arange(width)).ravel()
            picked = order[rows].reshape(-1, width)
            groups.append((self.flat_positions(slots[chosen]), ea[picked], eb[picked]))
        self._tables[id(clique)] = (clique, groups)
        return groups

    def pair_groups(self, pairs: np.ndarray) -> tuple:
        """Where pair terms go: the flat per-vertex-diagonal indices of both ends (the +C
        blocks, summed per vertex) and the off-diagonal blocks [(positions (S, 9), springs
        (S, M))], the springs whose -C add to each."""
        hit = self._tables.get(("pairs", id(pairs)))
        if hit is not None and hit[0] is pairs:
            return hit[1]
        if np.any(pairs[:, 0] == pairs[:, 1]):
            raise ValueError("a pair term needs two different vertices")
        groups = []
        for positions, a, b in self._groups(pairs):
            off = (a % 2) != (b % 2)  # members (0, 1) or (1, 0): the -C entries
            rows = off.all(axis=1)  # a block is either all off-diagonal entries or none
            if rows.any():
                groups.append((positions[rows], a[rows] // 2))
        ends = [(pairs[:, e].astype(np.int64)[:, None] * 9 + BLOCK).ravel() for e in (0, 1)]
        self._tables[("pairs", id(pairs))] = (pairs, (ends, groups))
        return ends, groups


class MatrixBuilder:
    """Fills a symmetric :class:`BlockMatrix` on a pattern; :meth:`finish` returns it."""

    def __init__(self, pattern: BlockPattern, out: np.ndarray | None = None):
        self.pattern = pattern
        if out is None:
            out = np.zeros(pattern.size)
        else:
            out.fill(0.0)  # reusing a buffer: its pages are already mapped (a big win in VMs)
        self._data = out
        self._diagonal = np.zeros(pattern.n * 9)

    def add_diagonal(self, index: np.ndarray, values: np.ndarray, flat=None) -> None:
        """Per-vertex blocks values (s, 3, 3) at vertices ``index`` (repeats summed); ``flat``:
        the precomputed flat indices index * 9 + component."""
        if flat is None:
            flat = (np.asarray(index, np.int64)[:, None] * 9 + BLOCK).ravel()
        self._diagonal += np.bincount(flat, weights=values.ravel(), minlength=len(self._diagonal))

    def add_pairs(self, pairs: np.ndarray, blocks: np.ndarray) -> None:
        """Pair terms: symmetric blocks C (s, 3, 3) on pairs (s, 2) of different vertices give
        [[C, -C], [-C, C]]."""
        ends, groups = self.pattern.pair_groups(pairs)
        for flat_end in ends:
            self.add_diagonal(None, blocks, flat_end)
        flat = blocks.reshape(-1, 9)
        for k, (positions, springs) in enumerate(groups):
            if springs.shape[1] == 1:  # one spring per block: no sum needed
                values = np.take(flat, springs[:, 0], axis=0, mode="clip",
                                 out=self.pattern.scratch(("pairs", k), positions.shape))
            else:
                values = np.take(flat, springs, axis=0, mode="clip").sum(axis=1)
            self._subtract(positions, values)

    def _subtract(self, positions: np.ndarray, values: np.ndarray) -> None:
        """data[positions] -= values for unique positions, through reused buffers (fresh
        megabyte temporaries cost more in page faults than the arithmetic)."""
        current = np.take(self._data, positions, mode="clip",
                          out=self.pattern.scratch(("data", positions.shape), positions.shape))
        current -= values
        np.put(self._data, positions, current, mode="clip")

    def add_rank_one(self, clique: np.ndarray, grad: np.ndarray, coefficient: float) -> None:
        """Rank-one terms c g g^T, g (m, k, 3) on the k vertices of each clique row (the
        Gauss-Newton bending Jacobian): block (a, b) = c g_a g_b^T."""
        table = grad.reshape(-1, 3)
        for positions, a, b in self.pattern._groups(clique):
            ga = np.take(table, a.T, axis=0, mode="clip").transpose(1, 2, 0)  # (S, 3, M)
            blocks = np.matmul(ga, np.take(table, b, axis=0, mode="clip"))  # summed over entries
            blocks *= -coefficient
            self._subtract(positions, blocks.reshape(-1, 9))  # (unique positions)

    def add_shared(self, clique: np.ndarray, blocks: np.ndarray, coefficient: float) -> None:
        """Terms c C_m (C (m, 3, 3) symmetric) on every pair of vertices of clique row m, each
        vertex with itself included: block (a, b) = c C_m (a force on a face's mean velocity,
        shared by its corners)."""
        k = clique.shape[1]
        table = blocks.reshape(-1, 9)
        for positions, a, _ in self.pattern._groups(clique):
            values = np.take(table, a // k, axis=0, mode="clip").sum(axis=1)
            values *= -coefficient
            self._subtract(positions, values)

    def finish(self) -> BlockMatrix:
        p = self.pattern
        data = self._data
        data[p.flat_positions(p.diagonal_slot).ravel()] += self._diagonal
        data[p._lower] = data[p._upper]  # symmetric: only row <= column blocks were filled
        return BlockMatrix(p, data.reshape(p.n, 3, 3 * p.width))


class BlockMatrix:
    """A symmetric matrix on a :class:`BlockPattern`: ``matrix @ u`` for u (n, 3)."""

    def __init__(self, pattern: BlockPattern, data: np.ndarray):
        self.pattern = pattern
        self.data = data  # (n, 3, width * 3): row i's blocks side by side
        # every row's neighbours' vectors side by side, reused by every product
        self._gathered = np.empty((pattern.n, pattern.width, 3))

    def __getstate__(self) -> dict:
        return {"pattern": self.pattern, "data": self.data}  # (the work buffer is not state)

    def __setstate__(self, state: dict) -> None:
        self.__init__(state["pattern"], state["data"])

    def __matmul__(self, u: np.ndarray) -> np.ndarray:
        p = self.pattern
        # whole rows of u (a fifth faster than gathering their x, y, z entries one by one);
        # mode="clip": the indices are valid by construction, and numpy's bounds-checked take
        # into an output buffer is twice as slow
        np.take(np.ascontiguousarray(u), p.neighbours, axis=0, out=self._gathered, mode="clip")
        # einsum: a quarter faster than matmul on these many small rows (n of 3 x 3 width)
        return np.einsum("nik,nk->ni", self.data, self._gathered.reshape(p.n, -1))

    def diagonal(self, vertices: np.ndarray | None = None) -> np.ndarray:
        """(n, 3, 3) diagonal blocks, or (k, 3, 3) those of ``vertices`` (k,)."""
        p = self.pattern
        rows = np.arange(p.n) if vertices is None else np.asarray(vertices, np.int64)
        column = p.diagonal_slot[rows] % p.width
        return self.data.reshape(p.n, 3, p.width, 3)[rows, :, column, :]
