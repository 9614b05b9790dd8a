"""The rows of rigid bodies' joints at the bodies' current poses, vectorised over joints.

Every joint has 6 equality rows (what it holds: the pivot's three directions, then three
turning directions; unused ones empty) and 4 clamped rows (lower and upper limit, motor,
spring). Each row is 12 numbers over [v_a, w_a, v_b, w_b] of its two bodies, as the contact
rows (:mod:`physanim.core.rigid.contact_solver`): a linear row along u is
[-u, -(r_a x u), u, r_b x u] with both lever arms to the midpoint of the two pivots (the impulse
and its reaction act at one point: angular momentum is conserved); an angular row about u is
[0, -u, 0, u]. Their solve is :mod:`.joint_solver`'s.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..transforms import cross
from .joint_chains import chains
from .joints import CONE_TWIST, FIXED, FRAME, HINGE, ROWS, SLIDER, SPRING_JOINT, JointModel


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
