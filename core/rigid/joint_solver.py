"""The soft-step solve of rigid bodies' joints, vectorised over joints (their rows at the
current poses: :mod:`.joint_rows`).

A pass (:func:`solve`) solves every row of every joint together — joints sharing a body
couple, so a chain is solved as a whole, not link by link — by conjugate gradients, with the
clamped rows in or out as they must be: a limit pushes only, like a contact; a motor is
bounded by its torque or force; a spring is Catto's soft constraint (exactly an implicit
damped spring). The soft step (Box2D v3's) runs it twice per sub-step: with position feedback
(JOINT_BIAS of the drift taken back), then, after the positions moved, without it (relax);
between the two the bodies are put back on their joints (:func:`displacement`).
"""
from __future__ import annotations

import numpy as np

from ..forces.springs import scatter_add
from ..transforms import cross
from .joint_chains import ChainSolver
from .joint_rows import EQ, LIMIT, MOTOR, SPRING, JointRows, _pinv
from .joint_rows import rows as rows  # (re-exported: the joints' rows are asked for here)
from .joints import ROWS


JOINT_BIAS = 0.2  # fraction of a joint's drift taken back per sub-step (with position feedback)
MAX_CORRECTION = 4.0  # [m/s], [rad/s] fastest drift correction
CG_TOLERANCE = 1e-6  # relative residual of the joints' equality solve
CG_ITERATIONS_PER_JOINT = 4
ACTIVE_SET_STEPS = 4  # solves per pass as limits let go or take part and motors saturate
def warm_start(vel: np.ndarray, r: JointRows, impulse: np.ndarray) -> None:
    """Apply the joints' accumulated impulses (J, ROWS) (from the last sub-step)."""
    if not len(r):
        return
    _apply(vel, r, impulse, slice(None))


def _apply(vel: np.ndarray, r: JointRows, impulse: np.ndarray, rows: slice) -> None:
    """Add the velocity changes of impulses (J, R) along the rows ``rows`` to ``vel``."""
    d = np.einsum("jr,jri->ji", impulse, r.mj[:, rows])
    scatter_add(vel, r.ab[:, 0], d[:, :6])
    scatter_add(vel, r.ab[:, 1], d[:, 6:])


def solve(vel: np.ndarray, r: JointRows, impulse: np.ndarray, h: float, use_bias: bool) -> None:
    """One pass over every joint together; ``impulse`` (J, ROWS) accumulated, updated in place.

    Each row's velocity target: the equality rows' drift taken back (JOINT_BIAS of it per
    sub-step, with position feedback) or held; a limit's gap closed within the sub-step and
    no further (a passed one pushed back like a drift); a motor's speed; a spring's soft
    equation. They are solved together (conjugate gradients on J M^-1 J^T plus the springs'
    softness), then the clamped rows are checked — a limit that would pull lets go, a motor
    beyond its strength pushes with all of it, a limit left approaching takes part — and the
    others solved again, at most ACTIVE_SET_STEPS times."""
    n = len(r)
    if not n:
        return
    gap = r.c[:, EQ:]
    passed = np.maximum(JOINT_BIAS / h * gap, -MAX_CORRECTION) if use_bias \
        else np.zeros_like(gap)
    target = np.zeros((n, ROWS))
    if use_bias:
        target[:, :EQ] = -np.clip(JOINT_BIAS / h * r.c[:, :EQ], -MAX_CORRECTION, MAX_CORRECTION)
    limit, motor, spring = r.kind == LIMIT, r.kind == MOTOR, r.kind == SPRING
    target[:, EQ:] = np.select([limit, motor, spring],
                               [-np.where(gap > 0.0, gap / h, passed), r.target,
                                -r.beta / h * gap], 0.0)
    soft = np.concatenate([np.zeros((n, EQ)), np.where(spring, r.gamma, 0.0)], axis=1)
    rel0 = np.einsum("jri,ji->jr", r.j, vel[r.ab].reshape(n, 12))
    bound = np.concatenate([np.zeros((n, EQ)), r.bound], axis=1)
    is_limit = np.concatenate([np.zeros((n, EQ), bool), limit], axis=1)
    is_motor = np.concatenate([np.zeros((n, EQ), bool), motor], axis=1)
    active = np.concatenate([r.holds, motor | spring | (limit & (
        (impulse[:, EQ:] > 0.0) | (rel0[:, EQ:] < target[:, EQ:])))], axis=1)
    let_go = np.zeros((n, ROWS), bool)  # limits that would pull: their impulse goes to 0
    saturated = np.zeros((n, ROWS), bool)  # motors beyond their strength: at it
    held = np.zeros((n, ROWS))  # the impulse change of rows at a bound
    # a motor driving into a limit on its own axis pushes with all its strength (the two rows
    # are one direction: solved together they would contradict each other)
    push = np.sign(target - rel0) * bound - impulse
    delta = np.zeros((n, ROWS))
    for _ in range(ACTIVE_SET_STEPS):
        stopped = (is_limit & active & ~let_go).any(axis=1)
        into = is_motor & stopped[:, None]
        fixed = let_go | saturated | into
        known = np.where(into, push, np.where(fixed, held, 0.0))
        free = active & ~fixed
        trial = vel
        if known.any():
            trial = vel.copy()
            _apply(trial, r, known, slice(None))
        rel = np.einsum("jri,ji->jr", r.j, trial[r.ab].reshape(n, 12))
        b = target - rel - soft * (impulse + known)
        op = _Rows(r, len(vel), free, soft)
        delta = known + op.split(_linear_solve(op, op.pack(b, 0.0)))[0] * free
        total = impulse + delta
        pull = is_limit & free & (total < 0.0)
        beyond = is_motor & free & (np.abs(total) > bound)
        waiting = is_limit & ~active  # limits left out: do they now approach?
        approach = waiting
        if waiting.any():
            after = rel + np.einsum("jri,ji->jr", r.j, _moved(r, len(vel), delta - known))
            approach = waiting & (after < target - 1e-9 * (np.abs(target) + 1e-3))
        if not (pull.any() or beyond.any() or approach.any()):
            break
        held = np.where(pull, -impulse, np.where(beyond, np.clip(total, -bound, bound) -
                                                   impulse, held))
        let_go |= pull
        saturated |= beyond
        active |= approach
    impulse += delta
    _apply(vel, r, delta, slice(None))


def _moved(r: JointRows, count: int, delta: np.ndarray) -> np.ndarray:
    """(J, 12) the velocity changes at each joint's two sides of the impulses ``delta``."""
    move = np.zeros((count, 6))
    _apply(move, r, delta, slice(None))
    return move[r.ab].reshape(len(r), 12)


def displacement(r: JointRows, count: int, momentum: np.ndarray | None = None,
                 inv_mass: np.ndarray | None = None, group: np.ndarray | None = None
                 ) -> np.ndarray:
    """(count, 6) the smallest moves [dx, dtheta] of the rows (by their inverse masses) that
    take every joint's equality errors and passed limits to zero, to first order
    (post-stabilisation, Cline & Pai: the positions are put back on the joints without
    touching the momenta).

    Moving bodies at fixed momenta changes the angular momentum about the origin by
    sum dx x P; a group of free bodies joined only to each other keeps it to first order:
    ``group`` (count,) labels such groups (-1: none), ``momentum`` (count, 3) and
    ``inv_mass`` (count,) of the rows, and their moves satisfy sum P x dx = 0 per group too."""
    move = np.zeros((count, 6))
    if not len(r):
        return move
    passed = (r.kind == LIMIT) & (r.c[:, EQ:] < 0.0)
    use = np.concatenate([r.holds, passed], axis=1)
    op = _Rows(r, count, use, None, momentum, inv_mass, group)
    return op.moves(_linear_solve(op, op.pack(-r.c, 0.0)))


def drift(r: JointRows) -> float:
    """The largest equality error or passed limit of the joints [m], [rad]."""
    if not len(r):
        return 0.0
    passed = np.where(r.kind == LIMIT, np.maximum(-r.c[:, EQ:], 0.0), 0.0)
    return float(max(np.abs(r.c[:, :EQ]).max(), passed.max()))


class _Rows:
    """The linear system J M^-1 J^T x (+ softness) = b over the rows ``use`` (J, ROWS) of every
    joint, and, per group of free joined bodies, 3 rows keeping its angular momentum (see
    :func:`displacement`); preconditioned by each joint's equality block and each other row's
    own effective mass."""

    def __init__(self, r, count, use, soft=None, momentum=None, inv_mass=None, group=None):
        self.r, self.count, self.use = r, count, use
        self.soft = np.zeros(use.shape) if soft is None else soft
        self.rows = np.nonzero(group >= 0)[0] if group is not None else np.zeros(0, np.int64)
        if len(self.rows):
            labels, self.member = np.unique(group[self.rows], return_inverse=True)
            self.groups = len(labels)
            self.p = momentum[self.rows]
            self.w = inv_mass[self.rows]
            pp = np.einsum("ki,kj->kij", self.p, self.p)
            cross = self.w[:, None, None] * (np.einsum("ki,ki->k", self.p, self.p)[:, None,
                                                                                    None]
                                             * np.eye(3) - pp)  # m^-1 [P]x [P]x^T
            diag = np.zeros((self.groups, 3, 3))
            np.add.at(diag, self.member, cross)
            self.group_block = _pinv(diag)
        else:
            self.groups = 0
        k = np.where(r.mass > 0.0, 1.0 / np.where(r.mass > 0.0, r.mass, 1.0), 0.0)
        self.inverse = np.where(k + self.soft > 0.0, 1.0 / np.where(k + self.soft > 0.0,
                                                                    k + self.soft, 1.0), 0.0)
        self.size = len(r) * ROWS + 3 * self.groups

    def pack(self, joint, group):
        out = np.zeros(self.size)
        n = len(self.r) * ROWS
        out[:n] = (np.asarray(joint) * self.use).ravel()
        out[n:] = np.broadcast_to(group, (3 * self.groups,))
        return out

    def split(self, x):
        n = len(self.r) * ROWS
        return x[:n].reshape(len(self.r), ROWS), x[n:].reshape(self.groups, 3)

    def moves(self, x):
        mu, nu = self.split(x)
        move = np.zeros((self.count, 6))
        _apply(move, self.r, mu * self.use, slice(None))
        if self.groups:
            move[self.rows, :3] += self.w[:, None] * cross(nu[self.member], self.p)
        return move

    def group_columns(self) -> np.ndarray:
        """(size, 3 G) the system's columns of the groups' rows (``self(e)`` for each unit
        vector e of them, all at once): a group's unit impulse along axis k moves its members
        by w (e_k x P), and only its own joints and its own rows see it."""
        r, n = self.r, len(self.r)
        g3 = 3 * self.groups
        out = np.zeros((self.size, g3))
        if not g3:
            return out
        axes = np.eye(3)
        move = np.zeros((3, self.count, 6))  # one move per axis, every group at once
        move[:, self.rows, :3] = self.w[:, None] * cross(axes[:, None], self.p[None])
        side = np.full(self.count, -1, np.int64)  # each row's group
        side[self.rows] = self.member
        block = out[:n * ROWS].reshape(n, ROWS, self.groups, 3)
        for k in range(2):  # each side of the joints: its group's columns see its rows
            rows = r.ab[:, k]
            owner = side[rows]
            mine = np.nonzero(owner >= 0)[0]
            seen = r.j[mine, :, 6 * k:6 * k + 6] @ move[:, rows[mine]].transpose(1, 2, 0)
            block[mine, :, owner[mine]] += seen * self.use[mine, :, None]
        turn = cross(self.p[None], move[:, self.rows, :3])  # (3, R, 3): P x move per axis
        group = np.zeros((self.groups, 3, 3))  # [group, row axis, column axis]
        np.add.at(group, self.member, turn.transpose(1, 2, 0))
        tail = out[n * ROWS:].reshape(self.groups, 3, self.groups, 3)
        tail[np.arange(self.groups), :, np.arange(self.groups), :] = group
        return out

    def __call__(self, x):
        move = self.moves(x)
        joint = np.einsum("jri,ji->jr", self.r.j, move[self.r.ab].reshape(len(self.r), 12)) + \
            self.soft * self.split(x)[0]
        group = np.zeros((self.groups, 3))
        if self.groups:
            np.add.at(group, self.member, cross(self.p, move[self.rows, :3]))
        return self.pack(joint, group.ravel())

    def precondition(self, x):
        mu, nu = self.split(x)
        inner = self.inverse * mu
        eq = self.use[:, :EQ] & self.r.holds
        inner[:, :EQ] = np.where(eq, np.einsum("jrs,js->jr", self.r.block, mu[:, :EQ] * eq),
                                 inner[:, :EQ])
        out = self.pack(inner, 0.0)
        if self.groups:
            out[len(self.r) * ROWS:] = np.einsum("gij,gj->gi", self.group_block, nu).ravel()
        return out


def _linear_solve(op, b: np.ndarray) -> np.ndarray:
    """x with op(x) = b: directly along chains (:mod:`.joint_chains`) where the joints form
    them, else by conjugate gradients."""
    if op.r.paths is not None:
        try:
            return ChainSolver(op, op.r.paths).solve(b)
        except np.linalg.LinAlgError:  # redundant joints (two hinges on one axis): iterate
            pass
    return _pcg(op, b)


def _pcg(op, b: np.ndarray) -> np.ndarray:
    """x with op(x) = b by conjugate gradients preconditioned by op.precondition, to a
    residual of CG_TOLERANCE of b, at most CG_ITERATIONS_PER_JOINT per row block + 10."""
    x = np.zeros_like(b)
    norm_b = np.linalg.norm(b)
    if norm_b == 0.0:
        return x
    res = b.copy()
    z = op.precondition(res)
    p = z.copy()
    rz = res @ z
    for _ in range(CG_ITERATIONS_PER_JOINT * (len(b) // EQ + 1) + 10):
        ap = op(p)
        pap = p @ ap
        if pap <= 0.0:
            break
        alpha = rz / pap
        x += alpha * p
        res -= alpha * ap
        if np.linalg.norm(res) <= CG_TOLERANCE * norm_b:
            break
        z = op.precondition(res)
        rz, old = res @ z, rz
        p = z + (rz / old) * p
    return x


def pivot_force(r: JointRows, impulse: np.ndarray, h: float) -> np.ndarray:
    """(J,) the force [N] each joint's pivot carried over the sub-step (its equality rows along
    the pivot's directions)."""
    return np.linalg.norm(impulse[:, :3], axis=1) / h
