"""The rigid bodies' joints within a frame: which hold, their FRAME
sides as extra rows after the bodies' (posed along the paths the caller gives), their rows
at the current poses, putting the bodies back on them after each move (post-stabilisation)
and breaking. The solve itself is :mod:`.joint_solver`; the frame's step is the solver's
(``step``: its bodies, velocities, inverse masses; ``inverse_inertia(step, q)`` its world
inverse inertias)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import TransformPath
from . import dynamics, sleep
from . import joint_solver as js_
from . import quaternion as quat
from .bodies import Posed
from .joints import FRAME

PROJECTIONS = 4  # Newton steps (at most) putting bodies back on their joints after a move
PROJECTION_TOLERANCE = 1e-7  # [m], [rad]: joints closer than this are left as they are
# within a frame, a sub-step's projection stops once a Newton step has shrunk the drift this
# much (the next sub-step's takes the rest); the frame's last goes to the tolerance
WITHIN_FRAME_GAIN = 100.0


@dataclass
class JointStep:
    """The frame's unbroken joints. Their FRAME sides are extra rows of
    the velocity array after the bodies' (``rows``), posed along ``frames``."""

    ids: np.ndarray  # (J,) model indices
    ab: np.ndarray  # (J, 2) rows of their sides
    impulse: np.ndarray  # (J, ROWS) accumulated impulses
    frames: Posed  # the FRAME sides' paths over the frame
    rows: np.ndarray  # (F,) their rows
    row_of: np.ndarray  # (joint count,) each joint's FRAME row (-1: none)
    x: np.ndarray  # (F, 3), (F, 3, 3): their poses now
    rot: np.ndarray
    solve: js_.JointRows | None = None
    posed_at: tuple | None = None  # what ``solve`` was built from (:func:`pose`)


def begin(model, step, live: np.ndarray, framed: np.ndarray) -> None:
    """The frame's joints: their FRAME sides posed along the given paths (or where they
    were placed), as rows after the bodies'."""
    joints = model.joints
    given = step.inputs.joint_paths
    paths = []
    for j in framed:
        m = given.get(int(j))
        paths.append(TransformPath(m[0], m[-1], m) if m is not None else
                     TransformPath(joints.joint_local_b[j], joints.joint_local_b[j]))
    frames = Posed(paths, np.zeros((len(framed), 3)))
    x, q = frames.pose(0.0)
    row_of = np.full(joints.joint_count, -1, np.int64)
    row_of[framed] = len(step.bodies) + np.arange(len(framed))
    step.joints = JointStep(np.zeros(0, np.int64), np.zeros((0, 2), np.int64),
                             np.zeros((0, js_.ROWS)), frames, row_of[framed], row_of, x,
                             quat.to_matrix(q))
    order(model, step, live)

def order(model, step, live: np.ndarray) -> None:
    """The joints ``live`` of the frame, their impulses taken from the State."""
    joints, js = model.joints, step.joints
    a = joints.joint_a[live]
    b = np.where(joints.joint_b[live] == FRAME, js.row_of[live], joints.joint_b[live])
    js.ids, js.ab = live, np.stack([a, b], axis=1)
    js.impulse = step.state.joints.joint_impulse[js.ids].copy()


def pose(model, step, inverse_inertia) -> None:
    """The joints' rows at the bodies' current poses: built again only when a pose, an inverse
    mass or the joints changed since they were last built (a sub-step asks after every move,
    and again where nothing moved: after the projection found the joints closed, and at the
    start of the next sub-step)."""
    js = step.joints
    if not len(js.ids):
        js.solve = None
        return
    b = step.bodies
    now = (js.ids, js.ab, b.x, b.q, js.x, js.rot, step.inv_mass, step.awake)
    if js.solve is not None and js.posed_at is not None and all(
            u.shape == v.shape and u.tobytes() == v.tobytes()
            for u, v in zip(now, js.posed_at)):
        return
    js.posed_at = tuple(u.copy() for u in now)
    f = len(js.rows)
    inv_inertia = inverse_inertia(step, b.q)
    js.solve = js_.rows(
        model.joints, js.ids, js.ab, np.concatenate([b.x, js.x]),
        np.concatenate([quat.to_matrix(b.q), js.rot]),
        np.concatenate([step.inv_mass, np.zeros(f)]),
        np.concatenate([inv_inertia, np.zeros((f, 3, 3))]), step.h)

def project(model, step, inverse_inertia, last: bool = True) -> None:
    """Put the bodies back on their joints after they moved (post-stabilisation: the
    positions only, PROJECTIONS Newton steps): a chain whipping round does not stretch
    however fast its links turn. The frame's ``last`` sub-step takes them to
    PROJECTION_TOLERANCE; the others stop sooner once a step has shrunk the drift
    WITHIN_FRAME_GAIN times (Newton's steps square it: the second would take a few
    micrometres to nothing, and the next sub-step's projection starts again anyway)."""
    js, b = step.joints, step.bodies
    if not len(js.ids):
        return
    d, m = step.awake, model
    L = dynamics.angular_momentum(b.q[d], m.body_inertia[d], step.w[d])
    rows = len(b) + len(js.rows)
    momentum = np.zeros((rows, 3))
    momentum[d] = m.body_mass[d, None] * step.v[d]
    inv_mass = np.concatenate([step.inv_mass, np.zeros(len(js.rows))])
    group = _free_groups(step, rows)
    enough = PROJECTION_TOLERANCE
    for _ in range(PROJECTIONS):
        pose(model, step, inverse_inertia)
        drift = js_.drift(js.solve)
        if drift <= enough:
            break
        if not last:
            enough = max(PROJECTION_TOLERANCE, drift / WITHIN_FRAME_GAIN)
        move = js_.displacement(js.solve, rows, momentum, inv_mass, group)
        b.x[d] += move[d, :3]
        b.q[d] = quat.normalized(quat.multiply(quat.from_rotation_vector(move[d, 3:]),
                                               b.q[d]))
    step.w[d] = dynamics.angular_velocity(b.q[d], m.body_inv_inertia[d], L)  # L kept

def _free_groups(step, rows: int) -> np.ndarray:
    """(rows,) a label for each body in a group of free bodies joined only to each other
    (their angular momentum is theirs to keep), -1 for the others."""
    js = step.joints
    a, b = js.ab[:, 0], js.ab[:, 1]
    dynamic = np.concatenate([step.bodies.dynamic, np.zeros(len(js.rows), bool)])
    label = sleep.islands(rows, a, b)
    held = np.zeros(rows, bool)  # groups with a side impulses do not move
    held[label[a[~dynamic[a] | ~dynamic[b]]]] = True
    joined = np.zeros(rows, bool)
    joined[a], joined[b] = True, True
    return np.where(joined & dynamic & ~held[label], label, -1)

def break_over(model, step, inverse_inertia) -> None:
    """Joints whose pivot carried more than their breaking force this sub-step break
    (recorded with the frame); the others are ordered again without them."""
    js, joints = step.joints, model.joints
    if js.solve is None:
        return
    snapped = js_.pivot_force(js.solve, js.impulse, step.h) > \
        joints.joint_break_force[js.ids]
    if not snapped.any():
        return
    state = step.state.joints
    state.joint_impulse[js.ids] = js.impulse
    gone = js.ids[snapped]
    state.joint_broken[gone] = True
    state.joint_broken_frame[gone] = step.inputs.frame
    state.joint_impulse[gone] = 0.0
    step.report.broken += [joints.joint_name[j] for j in gone]
    order(model, step, js.ids[~snapped])
    pose(model, step, inverse_inertia)
