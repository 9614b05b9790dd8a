"""A direct solve of the joints' linear system where the joints form chains.

Two joints couple when they share a body that impulses move; when no such body has more than
two joints and the joints close no loop, every group of coupled joints is a path — a rope, a
chain, a pendulum of pendulums, a bridge held at both ends — and the system is block
tridiagonal along each path. It is then solved exactly (Baraff's linear-time elimination of
Lagrange multipliers for the simplest tree) by block cyclic reduction: all paths and positions
together, in log2(L) vectorised levels for paths of L joints. (Block Thomas, one sweep down
each path and one back, cost a small inverse per joint in a Python loop along the path: most
of the chain benchmark's time. Parallel cyclic reduction, every position at every level, took
log2(L) times the inverses, which cost more than the loop saved.) Iterative solves need more and more iterations as a chain gets
longer; this stays exact.

The system is the one conjugate gradients would solve (:class:`.joint_solver._Rows`): each
joint's rows in use, springs' softness on the diagonal, and, for position projections, 3 rows
per group of free joined bodies (their angular momentum), which couple whole groups and are
taken in through their Schur complement.
"""
from __future__ import annotations

import functools

import numpy as np


def chains(ab: np.ndarray, moved: np.ndarray) -> list[np.ndarray] | None:
    """The joints (sides ``ab`` (J, 2); ``moved`` (J, 2): impulses move that side's body)
    ordered along paths, or None when a moved body has three or more joints or the joints
    close a loop. Read-only results, remembered for the last few joint sets (every sub-step
    asks again for the same joints: finding the paths is a Python walk along them)."""
    ab = np.ascontiguousarray(ab, np.int64)
    moved = np.ascontiguousarray(moved, bool)
    return _chains(ab.tobytes(), moved.tobytes(), len(ab))


@functools.lru_cache(maxsize=8)
def _chains(ab_bytes: bytes, moved_bytes: bytes, n: int) -> list[np.ndarray] | None:
    ab = np.frombuffer(ab_bytes, np.int64).reshape(n, 2)
    moved = np.frombuffer(moved_bytes, bool).reshape(n, 2)
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
    for path in out:
        path.setflags(write=False)
    return out


class _Layout:
    """How the joints lie along a set of paths (the same for every pose of those joints):
    ``index`` (C, L) each path's joints (-1 past its end), ``idx``/``pad`` the same clipped
    and where padded, ``shared`` (C, L - 1, 2, 2) which side of a joint is which side of the
    next (the body they share), and for chains (one body shared at most) ``side``: the
    take_along_axis indices of those sides, ``any_shared`` where there is one. Remembered
    for the last paths asked (:func:`chains` returns the same paths object for the same
    joints)."""

    _last: tuple | None = None

    def __init__(self, paths: list[np.ndarray], ab: np.ndarray):
        length = max(len(p) for p in paths)
        self.index = np.full((len(paths), length), -1, np.int64)
        for c, p in enumerate(paths):
            self.index[c, :len(p)] = p
        self.idx, self.pad = np.maximum(self.index, 0), self.index < 0
        ab = ab[self.idx]  # (C, L, 2)
        # the bodies a joint shares with the next along the path: side sa of one, sb of the
        # next (a body impulses do not move has zero inverse masses: its block is zero)
        self.shared = ab[:, :-1, :, None] == ab[:, 1:, None, :]  # (C, L - 1, sa, sb)
        self.side = None
        if (self.shared.sum(axis=(2, 3)) <= 1).all():
            side = np.argmax(self.shared.reshape(*self.shared.shape[:2], 4), axis=2)
            self.side = (side // 2)[..., None, None, None], (side % 2)[..., None, None, None]
            self.any_shared = self.shared.any(axis=(2, 3))[..., None, None]

    @classmethod
    def of(cls, paths: list[np.ndarray], ab: np.ndarray) -> _Layout:
        last = cls._last
        if last is not None and last[0] is paths and np.array_equal(last[1], ab):
            return last[2]
        layout = cls(paths, ab)
        cls._last = (paths, ab.copy(), layout)
        return layout


class ChainSolver:
    """The factorised system of :class:`.joint_solver._Rows` ``op`` over the paths ``paths``;
    :meth:`solve` takes the packed right-hand side to the packed solution."""

    def __init__(self, op, paths: list[np.ndarray]):
        r, rows = op.r, op.use.shape[1]
        self.op, self.rows = op, rows
        # the rows any joint uses (a hinge's five of ten): the blocks are that size
        self.cols = np.flatnonzero(op.use.any(axis=0)) if op.use.any() else np.arange(1)
        self.layout = _Layout.of(paths, r.ab)
        self.index = self.layout.index
        length = self.index.shape[1]
        key = (op.use.tobytes(), op.soft.tobytes())  # (the rows and paths are r's)
        factors = r.factors.get(key)
        if factors is None:
            factors = r.factors[key] = self._factor(r, op, length, len(paths))
        self.levels, self.inv = factors
        self.groups = op.groups
        if self.groups:  # the groups' rows: their coupling to the joints (B) and each other
            cols = op.group_columns()  # (size, 3 G)
            n = len(r) * rows
            self.b_ = cols[:n]
            self.c_ = cols[n:]
            inner = self._joint_solve(self.b_)
            self.schur = self.c_ - self.b_.T @ inner
            self.a_inv_b = inner

    def _factor(self, r, op, length: int, count: int) -> tuple[list, np.ndarray]:
        """The block-tridiagonal system along the paths (each joint's rows in use, the
        springs' softness on the diagonal, unused rows identity), reduced (:func:`reduce`)."""
        lay = self.layout
        idx, pad = lay.idx, lay.pad
        cols = self.cols
        rows = len(cols)
        use = op.use[idx[..., None], cols] & ~pad[..., None]  # (C, L, R): each path's joints
        j, mj = r.j[idx[..., None], cols], r.mj[idx[..., None], cols]
        # (matmul: three times as fast as einsum on these small blocks)
        diag = j @ mj.swapaxes(-1, -2) + np.eye(rows) * \
            op.soft[idx][..., cols][..., None, :]
        pair = use[..., :, None] & use[..., None, :]
        eye = np.eye(rows, dtype=bool)
        d = np.where(pair, diag, np.where(eye, 1.0, 0.0))
        upper = np.zeros((count, max(length - 1, 0), rows, rows))
        shared = lay.shared
        if lay.side is not None:  # one body at most shared (a chain): one product
            sa, sb = lay.side
            ja = np.take_along_axis(j[:, :-1].reshape(*upper.shape[:3], 2, 6), sa, 3)
            mb = np.take_along_axis(mj[:, 1:].reshape(*upper.shape[:3], 2, 6), sb, 3)
            block = ja[..., 0, :] @ mb[..., 0, :].swapaxes(-1, -2)
            upper += np.where(lay.any_shared, block, 0.0)
        else:
            for sa in range(2):
                for sb in range(2):
                    block = j[:, :-1, :, 6 * sa:6 * sa + 6] @ \
                        mj[:, 1:, :, 6 * sb:6 * sb + 6].swapaxes(-1, -2)
                    upper += np.where(shared[..., sa, sb, None, None], block, 0.0)
        return reduce(d, upper * (use[:, :-1, :, None] & use[:, 1:, None, :]))

    def _joint_solve(self, b: np.ndarray) -> np.ndarray:
        """A^-1 b for packed joint parts b (J * R, m)."""
        r, rows = self.op.r, self.rows
        m = b.shape[1]
        idx, pad = self.layout.idx, self.layout.pad
        x = reduced_solve(self.levels, self.inv, b.reshape(len(r), rows, m)[idx][..., self.cols, :]
                          * ~pad[..., None, None])
        out = np.zeros((len(r), rows, m))
        out[self.index[~pad][:, None], self.cols] = x[~pad]
        return (out * self.op.use[..., None]).reshape(len(r) * rows, m)

    def solve(self, b: np.ndarray) -> np.ndarray:
        n = len(self.op.r) * self.rows
        bj, bg = b[:n, None], b[n:]
        if not self.groups:
            return self._joint_solve(bj)[:, 0]
        inner = self._joint_solve(bj)[:, 0]
        y = np.linalg.lstsq(self.schur, bg - self.b_.T @ inner, rcond=None)[0]
        return np.concatenate([inner - self.a_inv_b @ y, y])


DENSE_WORK = 3e5  # a reduced system this small (paths x (positions x rows)^3) is inverted whole
SINGULAR = 1e-3  # an inverse this far from one (|M M^-1 - I|) is of a singular system


def _inverse(m: np.ndarray) -> np.ndarray:
    """Inverses of stacked square matrices. Redundant joints (a door on two hinges on one
    axis: ten rows holding five freedoms) make the system singular only to rounding: no pivot
    is exactly zero, so LAPACK returns an inverse, made of huge values that do not cancel. It
    is checked (M M^-1 = I), and a singular one raises LinAlgError: the caller then solves by
    conjugate gradients, which a consistent singular system does not trouble."""
    inv = np.linalg.inv(m)
    if np.abs(m @ inv - np.eye(m.shape[-1])).max() > SINGULAR:
        raise np.linalg.LinAlgError("the joints' chain system is singular (redundant joints)")
    return inv


def reduce(d: np.ndarray, u: np.ndarray) -> tuple[list, np.ndarray]:
    """Block cyclic reduction of C block-tridiagonal matrices: diagonal blocks d (C, L, R, R),
    blocks above the diagonal u (C, L - 1, R, R) (below it: their transposes). Each level
    eliminates the odd positions, folding them into their even neighbours, which leaves a
    block-tridiagonal system on the even positions, half as long; once it is small
    (DENSE_WORK) it is inverted whole (each level costs a dozen numpy steps however small
    its blocks: a 99-joint chain reduces 3 levels, not 7). About L small inverses in all, in
    log2(L) vectorised steps. Returns the levels — (alpha, gamma, the odd positions'
    inverses, their blocks below and above), alpha and gamma folding a right-hand side's odd
    positions into the even ones, from the left and the right — and the inverse of what is
    left (C, M R, M R) for its M positions; :func:`reduced_solve` uses them."""
    up = np.zeros_like(d)  # U_i: position i's coupling to the one after it
    up[:, :-1] = u
    low = np.zeros_like(d)  # L_i = U_(i-1)^T: to the one before
    low[:, 1:] = np.swapaxes(u, 2, 3)
    levels = []
    count, rows = d.shape[0], d.shape[2]
    while d.shape[1] > 1 and count * (d.shape[1] * rows) ** 3 > DENSE_WORK:
        even_d, odd_d = d[:, 0::2], d[:, 1::2]
        even_low, odd_low = low[:, 0::2], low[:, 1::2]
        even_up, odd_up = up[:, 0::2], up[:, 1::2]
        evens, odds = even_d.shape[1], odd_d.shape[1]
        inv = _inverse(odd_d)
        # even position 2t: odd t - 1 on its left, odd t on its right
        alpha, gamma = np.zeros_like(even_d), np.zeros_like(even_d)
        alpha[:, 1:] = -even_low[:, 1:] @ inv[:, :evens - 1]
        gamma[:, :odds] = -even_up[:, :odds] @ inv
        d = even_d.copy()
        d[:, 1:] += alpha[:, 1:] @ odd_up[:, :evens - 1]
        d[:, :odds] += gamma[:, :odds] @ odd_low
        low, up = np.zeros_like(d), np.zeros_like(d)
        low[:, 1:] = alpha[:, 1:] @ odd_low[:, :evens - 1]
        up[:, :odds] = gamma[:, :odds] @ odd_up
        levels.append((alpha, gamma, inv, odd_low, odd_up))
    m = d.shape[1]
    whole = np.zeros((count, m, rows, m, rows))
    at = np.arange(m)
    whole[:, at, :, at, :] = d.swapaxes(0, 1)
    whole[:, at[:-1], :, at[1:], :] = up[:, :-1].swapaxes(0, 1)
    whole[:, at[1:], :, at[:-1], :] = low[:, 1:].swapaxes(0, 1)
    return levels, _inverse(whole.reshape(count, m * rows, m * rows))


def reduced_solve(levels: list, inv: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x (C, L, R, m) solving the systems :func:`reduce` reduced, for right-hand sides b of
    the same shape: the right-hand side folded level by level, the last position solved, then
    the odd positions of each level back from their even neighbours."""
    odd_parts = []
    for alpha, gamma, _, _, _ in levels:
        even, odd = b[:, 0::2], b[:, 1::2]
        evens, odds = even.shape[1], odd.shape[1]
        b = even.copy()
        b[:, 1:] += alpha[:, 1:] @ odd[:, :evens - 1]
        b[:, :odds] += gamma[:, :odds] @ odd
        odd_parts.append(odd)
    c, m, rows = b.shape[:3]
    x = (inv @ b.reshape(c, m * rows, -1)).reshape(b.shape)
    for (_, _, odd_inv, odd_low, odd_up), odd in zip(reversed(levels), reversed(odd_parts)):
        evens, odds = x.shape[1], odd.shape[1]
        rhs = odd - odd_low @ x[:, :odds]
        right = min(odds, evens - 1)  # odd t has even t + 1 on its right
        rhs[:, :right] -= odd_up[:, :right] @ x[:, 1:right + 1]
        out = np.empty((x.shape[0], evens + odds) + x.shape[2:])
        out[:, 0::2], out[:, 1::2] = x, odd_inv @ rhs
        x = out
    return x
