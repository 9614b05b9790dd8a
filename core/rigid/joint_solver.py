"""Joint rows at the bodies' current poses and their soft-step solve, vectorised over joints.

Every joint has 6 equality rows (what it holds: the pivot's three directions, then three
turning directions; unused ones empty) and 4 clamped rows (lower and upper limit, motor,
spring). Each row is 12 numbers over [v_a, w_a, v_b, w_b] of its two bodies, as the contact
rows (:mod:`physanim.core.rigid.contact_solver`): a linear row along u is
[-u, -(r_a x u), u, r_b x u] with both lever arms to the midpoint of the two pivots (the impulse
and its reaction act at one point: angular momentum is conserved); an angular row about u is
[0, -u, 0, u].

A pass (:func:`solve`) solves every row of every joint together — joints sharing a body
couple, so a chain is solved as a whole, not link by link — by conjugate gradients, with the
clamped rows in or out as they must be: a limit pushes only, like a contact; a motor is
bounded by its torque or force; a spring is Catto's soft constraint (exactly an implicit
damped spring). The soft step (Box2D v3's) runs it twice per sub-step: with position feedback
(JOINT_BIAS of the drift taken back), then, after the positions moved, without it (relax);
between the two the bodies are put back on their joints (:func:`displacement`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..forces.springs import scatter_add
from ..transforms import cross
from .joint_chains import ChainSolver, chains
from .joints import CONE_TWIST, FIXED, FRAME, HINGE, ROWS, SLIDER, SPRING_JOINT, JointModel

JOINT_BIAS = 0.2  # fraction of a joint's drift taken back per sub-step (with position feedback)
MAX_CORRECTION = 4.0  # [m/s], [rad/s] fastest drift correction
CG_TOLERANCE = 1e-6  # relative residual of the joints' equality solve
CG_ITERATIONS_PER_JOINT = 4
ACTIVE_SET_STEPS = 4  # solves per pass as limits let go or take part and motors saturate
EQ = 6  # equality rows per joint
NONE, LIMIT, MOTOR, SPRING = range(4)  # what a clamped row is
# equality rows each kind holds: 3 pivot directions (the joint's x, y, z), 3 turning ones
_HOLDS = np.array([[1, 1, 1, 1, 1, 1],  # FIXED
                   [1, 1, 1, 0, 0, 0],  # BALL
                   [1, 1, 1, 1, 1, 0],  # HINGE (turning about x and y: z is free)
                   [1, 1, 0, 1, 1, 1],  # SLIDER (z is free)
                   [1, 1, 1, 0, 0, 0],  # CONE_TWIST
                   [0, 0, 0, 0, 0, 0]], bool)  # SPRING (its pivot rows are soft: clamped slots)


@dataclass
class JointRows:
    """The rows of the joints being solved, at the current poses.

    Attributes:
        joint: (J,) model index of each. ab: (J, 2) rows of its two sides in the velocity
            array.
        j, mj: (J, ROWS, 12) rows and the same times the inverse masses.
        holds: (J, EQ) active equality rows. block: (J, EQ, EQ) the inverse of their coupling
            (found when first asked for: only conjugate gradients' preconditioner uses it).
        c: (J, ROWS) position errors: equality rows' drift [m], [rad]; a limit's gap (>= 0:
            within it); a spring's stretch.
        mass: (J, ROWS) 1 / (J M^-1 J^T) of each row (0 for an empty one).
        kind: (J, 4) NONE, LIMIT, MOTOR or SPRING of each clamped row. target: (J, 4) a
            motor's velocity. bound: (J, 4) a motor's largest impulse in a sub-step.
        gamma, beta: (J, 4) a spring's softness (Catto: J v + beta / h C + gamma lambda = 0).
    """

    joint: np.ndarray
    ab: np.ndarray
    j: np.ndarray
    mj: np.ndarray
    holds: np.ndarray
    c: np.ndarray
    mass: np.ndarray
    kind: np.ndarray
    target: np.ndarray
    bound: np.ndarray
    gamma: np.ndarray
    beta: np.ndarray
    paths: list | None = None  # the joints along chains (a direct solve), None: not chains
    # the chains' factorisations of these rows, by the rows in use and softness
    # (:class:`.joint_chains.ChainSolver`): a sub-step's passes solve the same system again
    factors: dict = field(default_factory=dict)
    _block: np.ndarray | None = field(default=None, repr=False)

    def __len__(self) -> int:
        return len(self.joint)

    @property
    def block(self) -> np.ndarray:
        if self._block is None:
            holds = self.holds
            coupling = np.einsum("jri,jsi->jrs", self.j[:, :EQ], self.mj[:, :EQ])
            pair = holds[:, :, None] & holds[:, None, :]
            self._block = _pinv(np.where(pair, coupling, np.eye(EQ))) * pair
        return self._block


def rows(model: JointModel, joints: np.ndarray, ab: np.ndarray, x: np.ndarray,
         rot: np.ndarray, inv_mass: np.ndarray, inv_inertia: np.ndarray, h: float) -> JointRows:
    """The rows of ``joints`` (model indices) whose sides are the rows ``ab``
    (J, 2) of arrays over every row: centre x (N, 3), rotation rot (N, 3, 3) (a FRAME side's
    row holds the joint's world frame itself), inverse mass (N,) and world inverse inertia
    (N, 3, 3) (0 for rows impulses do not move); h [s] the sub-step."""
    n = len(joints)
    kind = model.joint_kind[joints]
    a, b = ab[:, 0], ab[:, 1]
    frame = model.joint_b[joints] == FRAME
    la, lb = model.joint_local_a[joints], model.joint_local_b[joints].copy()
    lb[frame] = np.eye(4)  # the row is the joint's frame
    wa = rot[a] @ la[:, :3, :3]  # (J, 3, 3) the joint's axes on each side
    wb = rot[b] @ lb[:, :3, :3]
    pa = x[a] + np.einsum("jik,jk->ji", rot[a], la[:, :3, 3])
    pb = x[b] + np.einsum("jik,jk->ji", rot[b], lb[:, :3, 3])
    mid = 0.5 * (pa + pb)
    ra, rb, gap = mid - x[a], mid - x[b], pb - pa
    axis_a, axis_b = wa[:, :, 2], wb[:, :, 2]

    j = np.zeros((n, ROWS, 12))
    c = np.zeros((n, ROWS))
    axes = wa.transpose(0, 2, 1)  # (J, 3, 3): the joint's x, y, z axes (on A) as rows
    pivot = _linear(axes, ra[:, None], rb[:, None])  # (J, 3, 12) the pivot along them
    j[:, :3] = pivot
    c[:, :3] = np.einsum("jik,ji->jk", wa, gap)  # the gap along the joint's axes
    swing = cross(axis_a, axis_b)
    j[:, 3:6] = _angular(axes)  # turning about the joint's axes
    # a hinge's turning errors are its axes' swing; those of joints that hold every turn
    # (fixed, slider) B's turn from A (ball and cone-twist hold none)
    c[:, 3:6] = np.einsum("jik,ji->jk", wa, swing)
    turns = (kind == FIXED) | (kind == SLIDER)
    if turns.any():
        c[turns, 3:6] = np.einsum("jik,ji->jk", wa[turns], _rotation_vector(
            wb[turns] @ axes[turns]))
    holds = _HOLDS[kind]
    j[:, :EQ] *= holds[:, :, None]
    c[:, :EQ] *= holds

    clamped = _clamped(model, joints, kind, wa, wb, axis_a, axis_b, swing, gap, ra, rb, h,
                       pivot)
    j[:, EQ:], c[:, EQ:] = clamped[0], clamped[1]
    ma, mb = inv_mass[a, None], inv_mass[b, None]
    mj = np.empty_like(j)
    mj[..., :3] = ma[:, None] * j[..., :3]
    # (matmul: einsum on these strided slices takes four times as long)
    mj[..., 3:6] = j[..., 3:6] @ inv_inertia[a].transpose(0, 2, 1)
    mj[..., 6:9] = mb[:, None] * j[..., 6:9]
    mj[..., 9:] = j[..., 9:] @ inv_inertia[b].transpose(0, 2, 1)
    k = np.einsum("jri,jri->jr", j, mj)
    mass = np.where(k > 1e-300, 1.0 / np.maximum(k, 1e-300), 0.0)
    moved = np.stack([inv_mass[a] > 0.0, inv_mass[b] > 0.0], axis=1)
    return JointRows(joints, ab, j, mj, holds, c, mass, *clamped[2:],
                     chains(ab, moved))


def _clamped(model, joints, kind, wa, wb, axis_a, axis_b, swing, gap, ra, rb, h, pivot):
    """The 4 clamped rows of each joint: (rows (J, 4, 12), errors (J, 4), kind (J, 4),
    target, bound, gamma, beta (J, 4)); ``pivot`` (J, 3, 12) the pivot's linear rows."""
    n = len(joints)
    j = np.zeros((n, 4, 12))
    c = np.zeros((n, 4))
    what = np.zeros((n, 4), np.int64)
    limits = model.joint_use_limits[joints]
    lower, upper = model.joint_lower[joints], model.joint_upper[joints]
    driven = (kind == HINGE) | (kind == SLIDER)
    on = driven & limits
    motor = driven & model.joint_use_motor[joints]
    spring = driven & model.joint_use_spring[joints] & \
        ((model.joint_stiffness[joints] > 0.0) | (model.joint_damping[joints] > 0.0))
    if (on | motor | spring).any():
        # the free coordinate of hinges (angle about z) and sliders (distance along z)
        angle = np.arctan2(np.einsum("ji,ji->j", wb[:, :, 0], wa[:, :, 1]),
                           np.einsum("ji,ji->j", wb[:, :, 0], wa[:, :, 0]))
        slide = np.einsum("ji,ji->j", axis_a, gap)
        # side A's coordinate relative to side B (the base: the world, a frame or the second
        # body): a hinged door turns by its angle, its motor turns it that way
        free = -np.where(kind == SLIDER, slide, angle)
        row = -np.where((kind == SLIDER)[:, None], pivot[:, 2], _angular(axis_a))
        j[on, 0], c[on, 0], what[on, 0] = row[on], (free - lower)[on], LIMIT
        j[on, 1], c[on, 1], what[on, 1] = -row[on], (upper - free)[on], LIMIT
        j[motor, 2], what[motor, 2] = row[motor], MOTOR
        j[spring, 3], c[spring, 3], what[spring, 3] = row[spring], free[spring], SPRING
    # cone-twist: B's axis within the cone, its twist within [lower, upper]
    cone = kind == CONE_TWIST
    if cone.any():
        sin = np.linalg.norm(swing, axis=1)
        phi = np.arctan2(sin, np.einsum("ji,ji->j", axis_a, axis_b))
        normal = np.where((sin > 1e-9)[:, None], swing / np.maximum(sin, 1e-300)[:, None],
                          wa[:, :, 0])
        j[cone, 0], c[cone, 0], what[cone, 0] = _angular(-normal)[cone], \
            (model.joint_cone[joints] - phi)[cone], LIMIT
        twist = -_twist(wa, wb, axis_b, normal, phi)  # A's relative to B's
        on = cone & limits
        j[on, 1], c[on, 1], what[on, 1] = _angular(-axis_a)[on], (twist - lower)[on], LIMIT
        j[on, 2], c[on, 2], what[on, 2] = _angular(axis_a)[on], (upper - twist)[on], LIMIT
    # a spring joint: its pivot's three directions as soft rows (slots 0, 1 and 3)
    sprung = kind == SPRING_JOINT
    for slot, i in zip((0, 1, 3), range(3) if sprung.any() else ()):
        j[sprung, slot] = pivot[sprung, i]
        c[sprung, slot] = np.einsum("ji,ji->j", wa[:, :, i], gap)[sprung]
        what[sprung, slot] = SPRING
    target = np.zeros((n, 4))
    target[:, 2] = model.joint_motor_velocity[joints]
    bound = np.zeros((n, 4))
    bound[:, 2] = model.joint_motor_max[joints] * h
    k, d = model.joint_stiffness[joints], model.joint_damping[joints]
    soft = d + h * k
    gamma = np.where(what == SPRING, np.where(soft > 0.0, 1.0 / (
        h * np.where(soft > 0.0, soft, 1.0)), 0.0)[:, None], 0.0)
    beta = np.where(what == SPRING, np.where(soft > 0.0, h * k / np.where(
        soft > 0.0, soft, 1.0), 0.0)[:, None], 0.0)
    return j, c, what, target, bound, gamma, beta


def _twist(wa, wb, axis_b, normal, phi) -> np.ndarray:
    """(J,) B's turn about A's z axis once its swing is undone [rad]: B's x axis taken back
    along the shortest rotation from B's z to A's, measured from A's x about A's z."""
    k = -normal  # the swing turns A's axis to B's about +normal: undo it
    x = wb[:, :, 0]
    cos, sin = np.cos(phi)[:, None], np.sin(phi)[:, None]
    back = x * cos + cross(k, x) * sin + k * np.einsum("ji,ji->j", k, x)[:, None] * (1 - cos)
    return np.arctan2(np.einsum("ji,ji->j", back, wa[:, :, 1]),
                      np.einsum("ji,ji->j", back, wa[:, :, 0]))


def _linear(u, ra, rb) -> np.ndarray:
    """(..., 12) rows along u (..., 3) with lever arms ra, rb (broadcast with u)."""
    out = np.empty(u.shape[:-1] + (12,))
    np.negative(u, out=out[..., :3])
    np.negative(cross(ra, u), out=out[..., 3:6])
    out[..., 6:9] = u
    cross(rb, u, out=out[..., 9:])
    return out


def _angular(u) -> np.ndarray:
    """(..., 12) rows turning about u (..., 3)."""
    out = np.zeros(u.shape[:-1] + (12,))
    np.negative(u, out=out[..., 3:6])
    out[..., 9:] = u
    return out


def _rotation_vector(m: np.ndarray) -> np.ndarray:
    """(J, 3) axis * angle of rotation matrices (J, 3, 3)."""
    v = 0.5 * np.stack([m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0],
                        m[:, 1, 0] - m[:, 0, 1]], axis=1)
    s = np.linalg.norm(v, axis=1)
    cos = 0.5 * (np.trace(m, axis1=1, axis2=2) - 1.0)
    angle = np.arctan2(s, cos)
    return v * np.where(s > 1e-12, angle / np.maximum(s, 1e-300), 1.0)[:, None]


def _pinv(k: np.ndarray) -> np.ndarray:
    """Pseudo-inverses of symmetric positive semi-definite matrices (g, n, n)."""
    if not len(k):
        return k.copy()
    value, vector = np.linalg.eigh(k)
    keep = value > 1e-12 * np.maximum(value[:, -1:], 1e-300)
    inverse = np.where(keep, 1.0 / np.where(keep, value, 1.0), 0.0)
    return np.einsum("gik,gk,gjk->gij", vector, inverse, vector)


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
    """x with op(x) = b (see :func:`_solver`)."""
    return _solver(op)(b)


def _solver(op):
    """b -> x with op(x) = b: directly along chains (:mod:`.joint_chains`, factorised here)
    where the joints form them, else by conjugate gradients."""
    if op.r.paths is not None:
        try:
            chain = ChainSolver(op, op.r.paths)
        except np.linalg.LinAlgError:  # redundant joints (two hinges on one axis): iterate
            pass
        else:
            return chain.solve
    return lambda b: _pcg(op, b)


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

