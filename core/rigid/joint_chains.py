"""A direct solve of the joints' linear system where the joints form chains.

Two joints couple when they share a body that impulses move; when no such body has more than
two joints and the joints close no loop, every group of coupled joints is a path — a rope, a
chain, a pendulum of pendulums, a bridge held at both ends — and the system is block
tridiagonal along each path. It is then solved exactly in one sweep down each path and one
back (block Thomas: Baraff's linear-time elimination of Lagrange multipliers for the simplest
tree), all paths together, position by position. Iterative solves need more and more
iterations as a chain gets longer; this stays one sweep.

The system is the one conjugate gradients would solve (:class:`.joint_solver._Rows`): each
joint's rows in use, springs' softness on the diagonal, and, for position projections, 3 rows
per group of free joined bodies (their angular momentum), which couple whole groups and are
taken in through their Schur complement.
"""
from __future__ import annotations

import numpy as np


def chains(ab: np.ndarray, moved: np.ndarray) -> list[np.ndarray] | None:
    """The joints (sides ``ab`` (J, 2); ``moved`` (J, 2): impulses move that side's body)
    ordered along paths, or None when a moved body has three or more joints or the joints
    close a loop."""
    n = len(ab)
    if not n:
        return []
    joints_of: dict[int, list[int]] = {}
    for j, ((a, b), (ma, mb)) in enumerate(zip(ab.tolist(), moved.tolist())):
        for side, on in {a: ma, b: mb}.items():
            if on:
                joints_of.setdefault(side, []).append(j)
    neighbours: list[set] = [set() for _ in range(n)]
    for js in joints_of.values():
        if len(js) > 2:
            return None
        if len(js) == 2 and js[0] != js[1]:
            neighbours[js[0]].add(js[1])
            neighbours[js[1]].add(js[0])
    if any(len(s) > 2 for s in neighbours):
        return None
    seen = np.zeros(n, bool)
    out = []
    for start in range(n):
        if seen[start] or len(neighbours[start]) == 2:
            continue
        path, here, before = [], start, -1
        while True:
            path.append(here)
            seen[here] = True
            nxt = [k for k in neighbours[here] if k != before]
            if not nxt:
                break
            before, here = here, nxt[0]
        out.append(np.array(path, np.int64))
    if not seen.all():  # what is left has two neighbours all round: loops
        return None
    return out


class ChainSolver:
    """The factorised system of :class:`.joint_solver._Rows` ``op`` over the paths ``paths``;
    :meth:`solve` takes the packed right-hand side to the packed solution."""

    def __init__(self, op, paths: list[np.ndarray]):
        r, rows = op.r, op.use.shape[1]
        self.op, self.rows = op, rows
        length = max(len(p) for p in paths)
        self.index = np.full((len(paths), length), -1, np.int64)
        for c, p in enumerate(paths):
            self.index[c, :len(p)] = p
        idx, pad = np.maximum(self.index, 0), self.index < 0
        use = op.use[idx] & ~pad[..., None]  # (C, L, R): each path's joints by position
        j, mj = r.j[idx][..., :rows, :], r.mj[idx][..., :rows, :]
        diag = np.einsum("clri,clsi->clrs", j, mj) + np.eye(rows) * op.soft[idx][..., None, :]
        pair = use[..., :, None] & use[..., None, :]
        eye = np.eye(rows, dtype=bool)
        self.d = np.where(pair, diag, np.where(eye, 1.0, 0.0))
        ab = r.ab[idx]  # (C, L, 2)
        upper = np.zeros((len(paths), max(length - 1, 0), rows, rows))
        for sa in range(2):  # the bodies a joint shares with the next along the path
            for sb in range(2):
                shared = ab[:, :-1, sa] == ab[:, 1:, sb]  # (a body impulses do not move
                # has zero inverse masses: its block is zero)
                block = np.einsum("clri,clsi->clrs", j[:, :-1, :, 6 * sa:6 * sa + 6],
                                  mj[:, 1:, :, 6 * sb:6 * sb + 6])
                upper += np.where(shared[..., None, None], block, 0.0)
        self.u = upper * (use[:, :-1, :, None] & use[:, 1:, None, :])
        self._factor()
        self.groups = op.groups
        if self.groups:  # the groups' rows: their coupling to the joints (B) and each other
            unit = np.eye(3 * self.groups)
            cols = [op(op.pack(np.zeros((len(r), rows)), unit[k])) for k in range(len(unit))]
            cols = np.array(cols).T  # (size, 3 G)
            n = len(r) * rows
            self.b_ = cols[:n]
            self.c_ = cols[n:]
            inner = self._joint_solve(self.b_)
            self.schur = self.c_ - self.b_.T @ inner
            self.a_inv_b = inner

    def _factor(self) -> None:
        """Forward elimination of the block-tridiagonal matrices, all paths at once: the
        inverses of the eliminated diagonal blocks (small inverses and products: numpy's
        batched solve with a matrix right-hand side is ten times slower)."""
        d = self.d.copy()
        inv = np.empty_like(d)
        inv[:, 0] = np.linalg.inv(d[:, 0])
        for k in range(1, d.shape[1]):
            lower = np.swapaxes(self.u[:, k - 1], 1, 2)
            d[:, k] -= lower @ inv[:, k - 1] @ self.u[:, k - 1]
            inv[:, k] = np.linalg.inv(d[:, k])
        self.inv = inv

    def _joint_solve(self, b: np.ndarray) -> np.ndarray:
        """A^-1 b for packed joint parts b (J * R, m)."""
        r, rows = self.op.r, self.rows
        m = b.shape[1]
        idx, pad = np.maximum(self.index, 0), self.index < 0
        y = b.reshape(len(r), rows, m)[idx] * ~pad[..., None, None]
        for k in range(1, y.shape[1]):
            y[:, k] -= np.swapaxes(self.u[:, k - 1], 1, 2) @ (self.inv[:, k - 1] @ y[:, k - 1])
        x = np.empty_like(y)
        last = y.shape[1] - 1
        x[:, last] = self.inv[:, last] @ y[:, last]
        for k in range(last - 1, -1, -1):
            x[:, k] = self.inv[:, k] @ (y[:, k] - self.u[:, k] @ x[:, k + 1])
        out = np.zeros((len(r), rows, m))
        out[self.index[~pad]] = x[~pad]
        return (out * self.op.use[..., None]).reshape(len(r) * rows, m)

    def solve(self, b: np.ndarray) -> np.ndarray:
        n = len(self.op.r) * self.rows
        bj, bg = b[:n, None], b[n:]
        if not self.groups:
            return self._joint_solve(bj)[:, 0]
        inner = self._joint_solve(bj)[:, 0]
        y = np.linalg.lstsq(self.schur, bg - self.b_.T @ inner, rcond=None)[0]
        return np.concatenate([inner - self.a_inv_b @ y, y])
