"""Aggregation multigrid preconditioner for the implicit spring-mesh solve.

Block Jacobi leaves conjugate gradients with a number of iterations that grows with the square
root of the stiffness (a stiff cloth at one step per frame needs hundreds): Jacobi only fixes
local error, and smooth, long-wave error travels one vertex per iteration. A coarse copy of the
mesh removes that long-wave error in one go. The coarse meshes come from the topology alone:
vertices are grouped into aggregates (a vertex and its untaken neighbours along springs, once
per topology), an aggregate moves as one (piecewise-constant prolongation P), and the coarse
matrix is the Galerkin product P^T A P — the fine blocks summed by aggregate pair, one
``np.bincount`` per level and linearisation — recursively down to about a hundred vertices,
solved exactly.

On the fine level the two parts are added (block Jacobi + P (coarse solve) P^T: no extra
product with the fine matrix per iteration, which is what costs in numpy); the coarse levels,
cheap, use a symmetric V-cycle (weighted-Jacobi pre- and post-smoothing). Both forms are
symmetric positive definite, so the whole is a valid CG preconditioner.
"""
from __future__ import annotations

import copy

import numpy as np

from ..transforms import inverse3, transform_vectors
from .sparse import BlockMatrix, BlockPattern

COARSEST = 120  # vertices: below this a level is solved directly (dense inverse, 360 x 360)
DIRECT_LIMIT = 400  # a coarsest level larger than this (aggregation stalled) gets Jacobi instead
SMOOTHING = 0.6  # coarse-level Jacobi weight: below 2 / lambda_max(D^-1 A) with margin (SPD V-cycle)


def aggregate(neighbours: np.ndarray) -> tuple[np.ndarray, int]:
    """Greedy aggregation on a pattern's neighbour table (n, width), each row padded with its
    own vertex: a vertex whose neighbours are all free starts an aggregate with them; leftovers
    join the aggregate of a neighbour. Returns (aggregate of every vertex, aggregate count)."""
    n = len(neighbours)
    owner = [-1] * n
    count = 0
    rows = neighbours.tolist()
    for v in range(n):
        if owner[v] < 0 and all(owner[u] < 0 for u in rows[v]):
            for u in rows[v]:
                owner[u] = count
            count += 1
    for v in range(n):
        if owner[v] < 0:
            owner[v] = next((owner[u] for u in rows[v] if owner[u] >= 0), -1)
            if owner[v] < 0:  # only reachable through later leftovers: its own aggregate
                owner[v] = count
                count += 1
    return np.array(owner, np.int64), count


class _Level:
    """A fine pattern, its aggregates and the map of its stored values onto the coarse ones."""

    def __init__(self, fine: BlockPattern, graph: np.ndarray | None = None):
        self.fine = fine
        self.owner, count = aggregate(fine.neighbours if graph is None else graph)
        self.flat_owner = (self.owner[:, None] * 3 + np.arange(3)).ravel()
        n, width = fine.n, fine.width
        rows = np.repeat(np.arange(n), width)
        a, b = self.owner[rows], self.owner[fine.neighbours.ravel()]
        coupled = a != b
        pairs = np.unique(np.stack([np.minimum(a, b), np.maximum(a, b)], 1)[coupled], axis=0)
        self.coarse = BlockPattern(count, [pairs])
        c = self.coarse
        slot = c._slot[np.searchsorted(c._key, a * c.n + b)]  # coarse block of every fine one
        positions = c.flat_positions(slot).reshape(n, width, 3, 3)  # [i, k, a, b]
        self._galerkin = positions.transpose(0, 2, 1, 3).ravel()  # in the data's (n, 3, k, 3) order

    def restrict(self, matrix: BlockMatrix) -> BlockMatrix:
        """P^T A P: every fine block summed into the block of its aggregates."""
        c = self.coarse
        data = np.bincount(self._galerkin, weights=matrix.data.ravel(), minlength=c.size)
        return BlockMatrix(c, data.reshape(c.n, 3, 3 * c.width))


class AggregationHierarchy:
    """The coarse patterns of one fine pattern (built once per topology); :meth:`preconditioner`
    builds the preconditioner for a matrix on it.

    Args: pattern: the fine pattern. graph: neighbour table (n, w) the fine vertices are
    aggregated along (default the pattern's own; the solver passes the springs', the strong
    couplings). coarsest: vertex count solved directly."""

    def __init__(self, pattern: BlockPattern, graph: np.ndarray | None = None,
                 coarsest: int = COARSEST):
        self.pattern = pattern
        self.levels: list[_Level] = []
        current = pattern
        while current.n > coarsest:
            level = _Level(current, graph if current is pattern else None)
            if level.coarse.n > 0.7 * current.n:
                break  # aggregation stalled (e.g. a mesh of loose vertices): solve here
            self.levels.append(level)
            current = level.coarse

    def preconditioner(self, matrix: BlockMatrix) -> VCycle:
        """u -> approximately A^-1 u, (n, 3) -> (n, 3)."""
        return VCycle(self.levels, matrix)


class VCycle:
    """One V-cycle of the hierarchy on a matrix: a callable r -> approximately A^-1 r, (n, 3)
    -> (n, 3). A plain object (not a closure) so a bake's state can be saved and resumed."""

    def __init__(self, levels: list, matrix: BlockMatrix):
        self.levels = levels
        self.matrices = [matrix]
        for level in levels:
            self.matrices.append(level.restrict(self.matrices[-1]))
        self.inverses = [inverse3(m.diagonal()) for m in self.matrices]
        last = self.matrices[-1]
        self.inverse = np.linalg.inv(_dense(last)) if last.pattern.n <= DIRECT_LIMIT else None

    def __call__(self, r: np.ndarray) -> np.ndarray:
        return self._cycle(0, r)

    def with_fine(self, vertices: np.ndarray, inverse: np.ndarray) -> VCycle:
        """A copy whose finest block-Jacobi inverses at ``vertices`` (k,) are ``inverse``
        (k, 3, 3) (the coarse levels shared)."""
        out = copy.copy(self)
        out.inverses = [self.inverses[0].copy(), *self.inverses[1:]]
        out.inverses[0][vertices] = inverse
        return out

    @staticmethod
    def _restrict(level: _Level, r: np.ndarray) -> np.ndarray:
        """P^T r: the residuals of every aggregate summed."""
        return np.bincount(level.flat_owner, weights=r.ravel(),
                           minlength=3 * level.coarse.n).reshape(-1, 3)

    def _cycle(self, depth: int, r: np.ndarray) -> np.ndarray:
        levels, inverses = self.levels, self.inverses
        if depth == len(levels):
            if self.inverse is None:
                return transform_vectors(inverses[depth], r)
            return (self.inverse @ r.ravel()).reshape(r.shape)
        a, level = self.matrices[depth], levels[depth]
        jacobi = transform_vectors(inverses[depth], r)
        if depth == 0:  # additive: Jacobi + coarse correction, no product with A
            return jacobi + np.take(self._cycle(1, self._restrict(level, r)), level.owner,
                                    axis=0, mode="clip")
        x = SMOOTHING * jacobi
        x += np.take(self._cycle(depth + 1, self._restrict(level, r - a @ x)), level.owner,
                     axis=0, mode="clip")
        x += SMOOTHING * transform_vectors(inverses[depth], r - a @ x)
        return x


def _dense(matrix: BlockMatrix) -> np.ndarray:
    """The (3n, 3n) dense matrix of a (small) block matrix."""
    p = matrix.pattern
    rows = (np.arange(p.n)[:, None, None] * 3 + np.arange(3)[None, :, None])  # (n, 3, 1)
    cols = (p.neighbours[:, None, :, None] * 3 + np.arange(3)).reshape(p.n, 1, 3 * p.width)
    dense = np.zeros((3 * p.n, 3 * p.n))
    np.add.at(dense, (np.broadcast_to(rows, matrix.data.shape),
                      np.broadcast_to(cols, matrix.data.shape)), matrix.data)
    return dense
