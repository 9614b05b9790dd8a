"""Rigid-body joints against closed forms: a pendulum's period, chains that do not stretch,
motors at their speed, limits held, breaking at the threshold, momentum kept."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from physanim.core.rigid.joints import FRAME, JointSettings
from physanim.core.errors import PhysanimError
from physanim.core.rigid import quaternion as quat
from physanim.core.rigid.model import RigidBodyBuilder
from physanim.core.rigid.solver import RigidBodySolver, RigidFrameInputs
from physanim.tests.core.rigid_helpers import DT, box, ground, sphere

G = 9.81


def joint_frame(pivot, z=(0.0, 0.0, 1.0)) -> np.ndarray:
    """A joint's world matrix: origin ``pivot``, z axis ``z`` (x, y completing it)."""
    z = np.asarray(z, float) / np.linalg.norm(z)
    helper = (1.0, 0.0, 0.0) if abs(z[0]) < 0.9 else (0.0, 1.0, 0.0)
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    m = np.eye(4)
    m[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    m[:3, 3] = pivot
    return m


def build(bodies, joints):
    b = RigidBodyBuilder()
    for body in bodies:
        b.add_body(body)
    for j in joints:
        b.add_joint(j)
    model = b.finalize()
    return model, RigidBodySolver(model), model.state()


def run(solver, state, frames, colliders=(), gravity=(0.0, 0.0, -G), each=None, paths=None):
    reports = []
    for f in range(frames):
        inputs = RigidFrameInputs(f, f * DT, DT, gravity, list(colliders),
                                  joint_paths=paths(f) if paths else {})
        reports.append(solver.advance(state, inputs))
        if each is not None:
            each(f + 1, state)
    return reports


def test_a_ball_joint_pendulum_swings_with_the_physical_pendulums_period():
    """A 5 cm ball 1 m below a ball joint, let go 0.1 rad out: T = 2 pi sqrt(I / (m g L)),
    I = m (L^2 + 2/5 r^2) about the pivot, times 1 + theta^2 / 16 for the amplitude; the
    joint holds the ball at L to 1e-6 L."""
    length, r, theta = 1.0, 0.05, 0.1
    _, solver, state = build(
        [sphere("Bob", r, (length * math.sin(theta), 0.0, -length * math.cos(theta)),
                linear_damping=0.0, angular_damping=0.0)],
        [JointSettings("Pivot", "BALL", 0)])
    xs = []
    run(solver, state, int(10 / DT), each=lambda f, s: xs.append(s.body_x[0].copy()))
    xs = np.array(xs)
    assert np.abs(np.linalg.norm(xs, axis=1) - length).max() < 1e-6 * length
    t = (np.arange(len(xs)) + 1) * DT
    x = xs[:, 0]
    down = np.nonzero((x[:-1] > 0) & (x[1:] <= 0))[0]
    crossing = t[down] + DT * x[down] / (x[down] - x[down + 1])
    period = np.diff(crossing).mean()
    expected = 2 * math.pi * math.sqrt((length ** 2 + 0.4 * r ** 2) / (G * length)) * \
        (1 + theta ** 2 / 16)
    assert period == pytest.approx(expected, rel=1e-3)


@pytest.mark.parametrize("kind", ["BALL", "HINGE"])
def test_a_twenty_link_chain_swung_hard_never_stretches(kind):
    """20 links of 0.3 m hang from the world and are swung at 8 m/s: the chain whips round,
    and no joint opens by more than 0.1 % of a link in 5 s (the whole chain: less)."""
    n, link = 20, 0.3
    top = np.array([0.0, 0.0, 7.0])
    down = tuple(quat.from_rotation_vector(np.array([[0.0, math.pi / 2, 0.0]]))[0])
    bodies = [box(f"Link{i}", (link / 2, 0.03, 0.03), top - (0, 0, (i + 0.5) * link),
                  orientation=down, velocity=(8.0, 0.0, 0.0)) for i in range(n)]
    axis = (0.0, 1.0, 0.0)
    joints = [JointSettings("Top", kind, 0, matrix=joint_frame(top, axis))] + \
        [JointSettings(f"J{i}", kind, i - 1, i, matrix=joint_frame(top - (0, 0, i * link), axis))
         for i in range(1, n)]
    _, solver, state = build(bodies, joints)
    worst = []

    def gaps(f, s):
        ends = s.body_x[:, None] + quat.to_matrix(s.body_q)[:, None, :, 0] * \
            np.array([-1.0, 1.0])[None, :, None] * link / 2  # (n, 2, 3): top end, bottom end
        worst.append(max(np.linalg.norm(ends[0, 0] - top),
                         np.linalg.norm(ends[1:, 0] - ends[:-1, 1], axis=1).max()))
    run(solver, state, int(5 / DT), each=gaps)
    assert max(worst) < 1e-3 * link
    assert state.body_x[-1, 2] < top[2] - 1.0  # it swung (it did not freeze)


def door(use_motor=True, use_limits=False, upper=1.0):
    """A 1 m x 2 m, 20 kg door hinged at its left edge about the vertical."""
    hinge = JointSettings("Hinge", "HINGE", 0, matrix=joint_frame((0.0, 0.0, 1.0)),
                          use_motor=use_motor, motor_velocity=2.0, motor_max=50.0,
                          use_limits=use_limits, lower=-1.0, upper=upper)
    return build([box("Door", (0.5, 0.025, 1.0), (0.5, 0.0, 1.0), mass=20.0,
                      angular_damping=0.0)], [hinge])


def hinge_angle(state) -> float:
    x = quat.to_matrix(state.body_q)[0][:, 0]
    return math.atan2(x[1], x[0])


def test_a_hinge_motor_turns_a_door_at_its_target_speed():
    """The motor's 50 N m spins the door (I = 20 (1 + 0.05^2) / 3 about its hinge) up to
    2 rad/s, which it then holds within 2 %; the hinge keeps the door upright."""
    _, solver, state = door()
    run(solver, state, int(1.5 / DT))
    w = quat.rotate(state.body_q, np.zeros((1, 3)))  # noqa: F841 (orientation is unit)
    inertia = solver.model.body_inertia[0]
    world_w = quat.to_matrix(state.body_q)[0] @ np.linalg.solve(
        inertia, quat.to_matrix(state.body_q)[0].T @ state.body_L[0])
    assert world_w[2] == pytest.approx(2.0, rel=0.02)
    assert np.abs(world_w[:2]).max() < 1e-3
    z = quat.to_matrix(state.body_q)[0][:, 2]
    assert z[2] > 1 - 1e-6  # upright


def test_a_hinge_limit_stops_the_door_and_is_never_passed():
    _, solver, state = door(use_limits=True, upper=1.0)
    angles = []
    run(solver, state, int(3 / DT), each=lambda f, s: angles.append(hinge_angle(s)))
    assert max(angles) < 1.0 + 1e-3
    assert angles[-1] == pytest.approx(1.0, abs=1e-2)  # pushed against it by the motor


@pytest.mark.parametrize("factor, breaks", [(1.01, False), (0.99, True)])
def test_a_joint_breaks_at_its_threshold(factor, breaks):
    """A 3 kg box hangs from a ball joint: the joint carries m g. A threshold 1 % above holds
    it; 1 % below, it breaks in the first frame and the box falls freely from there."""
    m = 3.0
    _, solver, state = build([box("Box", (0.1, 0.1, 0.1), (0.0, 0.0, -0.1), mass=m,
                                  linear_damping=0.0)],
                             [JointSettings("Hook", "BALL", 0, break_force=factor * m * G)])
    reports = run(solver, state, int(2 / DT))
    assert bool(state.joints.joint_broken[0]) == breaks
    if breaks:
        assert state.joints.joint_broken_frame[0] == 0 and reports[0].broken == ["Hook"]
        fall = -0.1 - 0.5 * G * 2.0 ** 2
        assert state.body_x[0, 2] == pytest.approx(fall, rel=0.02)
    else:
        assert np.abs(state.body_x[0] - (0.0, 0.0, -0.1)).max() < 1e-6


def test_joined_bodies_keep_their_momentum_with_gravity_off():
    """Two boxes on a hinge, thrown and spun in zero gravity: the joint's impulses are equal
    and opposite at one point, and putting them back on the joint after each move keeps the
    pair's angular momentum too: both to 1e-9."""
    bodies = [box("A", (0.2, 0.1, 0.1), (0.0, 0.0, 0.0), mass=2.0, velocity=(1.0, 0.5, 0.0),
                  angular_velocity=(0.0, 0.0, 3.0), linear_damping=0.0, angular_damping=0.0),
              box("B", (0.2, 0.1, 0.1), (0.4, 0.0, 0.0), mass=1.0, velocity=(0.0, -1.0, 0.5),
                  angular_velocity=(1.0, 0.0, 0.0), linear_damping=0.0, angular_damping=0.0)]
    _, solver, state = build(bodies, [JointSettings("Hinge", "HINGE", 0, 1,
                                                    matrix=joint_frame((0.2, 0.0, 0.0),
                                                                       (0.0, 1.0, 0.0)))])

    def momenta(s):
        return s.body_P.sum(axis=0), (np.cross(s.body_x, s.body_P) + s.body_L).sum(axis=0)
    p0, l0 = momenta(state)
    run(solver, state, 48, gravity=(0.0, 0.0, 0.0))
    p1, l1 = momenta(state)
    assert np.abs(p1 - p0).max() < 1e-9 * np.linalg.norm(p0)
    assert np.abs(l1 - l0).max() < 1e-9 * np.linalg.norm(l0)


def test_a_fixed_joint_welds_two_boxes_into_one():
    """Welded boxes thrown spinning: they keep their relative pose to 1e-6."""
    bodies = [box("A", (0.2, 0.1, 0.1), (0.0, 0.0, 0.0), angular_velocity=(0.0, 2.0, 3.0)),
              box("B", (0.1, 0.1, 0.3), (0.3, 0.0, 0.0))]
    _, solver, state = build(bodies, [JointSettings("Weld", "FIXED", 0, 1,
                                                    matrix=joint_frame((0.2, 0.0, 0.0)))])

    def relative(s):
        r = quat.to_matrix(s.body_q)
        return r[0].T @ r[1], r[0].T @ (s.body_x[1] - s.body_x[0])
    r0, d0 = relative(state)
    run(solver, state, 48, gravity=(0.0, 0.0, 0.0))
    r1, d1 = relative(state)
    assert np.abs(r1 - r0).max() < 1e-6 and np.abs(d1 - d0).max() < 1e-6


def test_a_slider_with_a_motor_moves_along_its_axis_only_and_stops_at_its_limits():
    """A box on a slider along x from the world, gravity pulling down: the motor drives it at
    0.5 m/s to the upper limit 0.3 m, which holds; it never drops."""
    slider = JointSettings("Rail", "SLIDER", 0, matrix=joint_frame((0.0, 0.0, 1.0),
                                                                  (1.0, 0.0, 0.0)),
                           use_motor=True, motor_velocity=0.5, motor_max=100.0,
                           use_limits=True, lower=-0.3, upper=0.3)
    _, solver, state = build([box("Cart", (0.1, 0.1, 0.1), (0.0, 0.0, 1.0))], [slider])
    xs = []
    run(solver, state, int(0.3 / DT), each=lambda f, s: xs.append(s.body_x[0].copy()))
    speed = (xs[-1][0] - xs[-3][0]) / (2 * DT)
    assert speed == pytest.approx(0.5, rel=0.02)
    run(solver, state, int(1.5 / DT), each=lambda f, s: xs.append(s.body_x[0].copy()))
    xs = np.array(xs)
    assert xs[:, 0].max() < 0.3 + 1e-3 and xs[-1, 0] == pytest.approx(0.3, abs=1e-2)
    assert np.abs(xs[:, 1:] - (0.0, 1.0)).max() < 1e-6


def test_a_cone_twist_joint_keeps_the_swing_within_its_cone():
    """A pendulum on a cone-twist joint with a 0.3 rad cone, let go 1 rad out: it swings no
    further than the cone (to 0.01 rad)."""
    cone = JointSettings("Shoulder", "CONE_TWIST", 0, matrix=joint_frame((0.0, 0.0, 0.0),
                                                                        (0.0, 0.0, -1.0)),
                         cone=0.3)
    theta = 0.3
    _, solver, state = build([box("Arm", (0.05, 0.05, 0.3), (0.0, 0.0, -0.3), mass=1.0,
                                  velocity=(3.0, 0.0, 0.0))], [cone])
    swing = []
    run(solver, state, int(2 / DT), each=lambda f, s: swing.append(math.acos(np.clip(
        quat.to_matrix(s.body_q)[0][2, 2], -1.0, 1.0))))
    assert max(swing) < theta + 0.01
    assert max(swing) > theta - 0.05  # it reached the cone


def test_a_joint_between_overlapping_bodies_keeps_them_from_pushing_apart():
    """Two boxes overlapping by 10 cm joined by a ball joint (collisions between them off by
    default) float in zero gravity without moving."""
    bodies = [box("A", (0.2, 0.2, 0.2), (0.0, 0.0, 0.0)), box("B", (0.2, 0.2, 0.2),
                                                               (0.3, 0.0, 0.0))]
    _, solver, state = build(bodies, [JointSettings("Pin", "BALL", 0, 1,
                                                    matrix=joint_frame((0.15, 0.0, 0.0)))])
    run(solver, state, 24, gravity=(0.0, 0.0, 0.0))
    assert np.abs(state.body_P).max() < 1e-9


def test_a_body_hangs_from_an_animated_frame_and_follows_it():
    """A ball joint's frame side moves 1 m along x in a second (the caller's path, frame by
    frame): the box hanging from it follows, its pivot on the frame to 1e-6 m."""
    _, solver, state = build([box("Box", (0.1, 0.1, 0.1), (0.0, 0.0, 1.0))],
                             [JointSettings("Hook", "BALL", 0, matrix=joint_frame(
                                 (0.0, 0.0, 1.1)))])

    def paths(f):
        out = []
        for k in range(3):
            m = joint_frame((min(1.0, (f + k / 2) * DT), 0.0, 1.1))
            out.append(m)
        return {0: np.array(out)}
    run(solver, state, int(1.5 / DT), paths=paths)
    pivot = state.body_x[0] + quat.to_matrix(state.body_q)[0] @ np.array([0.0, 0.0, 0.1])
    assert np.abs(pivot - (1.0, 0.0, 1.1)).max() < 1e-6


def test_joint_settings_errors_name_the_joint_and_the_value():
    with pytest.raises(PhysanimError, match='"Hinge".*lower limit 1 is above the upper 0'):
        JointSettings("Hinge", "HINGE", 0, use_limits=True, lower=1.0, upper=0.0)
    with pytest.raises(PhysanimError, match='"J".*unknown type'):
        JointSettings("J", "ROPE", 0)
    with pytest.raises(PhysanimError, match="itself"):
        JointSettings("J", "BALL", 1, 1)
    with pytest.raises(PhysanimError, match="names body 3 of 1"):
        build([box("A", (0.1,) * 3, (0.0, 0.0, 0.0))], [JointSettings("J", "BALL", 0, 3)])
    assert FRAME == -1


def test_a_chain_resting_on_the_ground_sleeps():
    """A 5-link chain lying on the ground comes to rest and falls asleep with its joints."""
    links = [box(f"L{i}", (0.15, 0.03, 0.03), (0.3 * i, 0.0, 0.03)) for i in range(5)]
    joints = [JointSettings(f"J{i}", "BALL", i - 1, i, matrix=joint_frame((0.3 * i - 0.15,
                                                                           0.0, 0.03)))
              for i in range(1, 5)]
    _, solver, state = build(links, joints)
    run(solver, state, 48, colliders=[ground()])
    assert state.body_asleep.all()


def test_newtons_cradle_one_in_one_out():
    """Five 10 cm balls (restitution 1) hang 1 m below hinges, 1 mm apart; the first is let go
    0.5 rad out. It stops dead on the row and the last one flies out carrying its momentum to
    2 % (it rises to (0.98)^2 of the first one's drop), the middle three barely stir (1 mm);
    then it swings back and the first one goes out again."""
    r, length, n, gap, theta = 0.1, 1.0, 5, 0.001, 0.5
    bodies, joints = [], []
    for i in range(n):
        x = i * (2 * r + gap)
        out = -theta if i == 0 else 0.0
        bodies.append(sphere(f"Ball{i}", r, (x + length * math.sin(out), 0.0,
                                               2.0 - length * math.cos(out)),
                             restitution=1.0, linear_damping=0.0, angular_damping=0.0))
        joints.append(JointSettings(f"Hinge{i}", "HINGE", i,
                                    matrix=joint_frame((x, 0.0, 2.0), (0.0, 1.0, 0.0))))
    _, solver, state = build(bodies, joints)
    z = []
    run(solver, state, int(2.2 / DT), each=lambda f, s: z.append(s.body_x[:, 2].copy()))
    rise = np.array(z) - (2.0 - length)
    drop = length * (1 - math.cos(theta))
    hit, first = int(0.6 / DT), int(1.0 / DT)  # after the impact (a quarter period, 0.5 s);
    # the last ball's swing out and back
    assert rise[:first, -1].max() > 0.98 ** 2 * drop
    assert np.abs(rise[:first, 1:-1]).max() < 1e-3
    assert rise[hit:first, 0].max() < 0.05 * drop  # the first ball stopped on the row
    assert rise[first:, 0].max() > 0.9 * drop  # ... and goes out again when it swings back


def _disturbed_chain(anchored: bool, n: int = 12, link: float = 0.3):
    """A chain of n links (hinges and balls by turns; hung from the world by a ball when
    ``anchored``) run 3 frames, then its joints' rows at a slightly disturbed pose: (rows,
    row count, momenta, inverse masses, the whole chain one free group unless anchored)."""
    from physanim.core.rigid import joint_solver as js

    bodies = [box(f"L{i}", (link / 2, 0.03, 0.03), ((i + 0.5) * link, 0.0, 2.0),
                  velocity=(0.0, 0.0, 0.3 * i), angular_velocity=(0.0, 1.0, 0.2))
              for i in range(n)]
    joints = [JointSettings(f"J{i}", "HINGE" if i % 2 else "BALL", i - 1, i,
                            matrix=joint_frame((i * link, 0.0, 2.0), (0.0, 1.0, 0.0)))
              for i in range(1, n)]
    if anchored:
        joints.insert(0, JointSettings("Top", "BALL", 0, matrix=joint_frame((0, 0, 2.0))))
    _, solver, state = build(bodies, joints)
    run(solver, state, 3, gravity=(0.0, 0.0, -G))
    model = solver.model
    x, q = state.body_x.copy(), state.body_q.copy()
    # the rows at a slightly disturbed pose: equality errors to remove
    x += np.random.default_rng(3).normal(scale=1e-3, size=x.shape)
    frame = np.eye(4)[None].repeat(1, axis=0)
    rot = np.concatenate([quat.to_matrix(q), frame[:, :3, :3]])
    inv_inertia = np.concatenate([quat.to_matrix(q) @ model.body_inv_inertia @
                                  np.swapaxes(quat.to_matrix(q), 1, 2), np.zeros((1, 3, 3))])
    ids = np.arange(model.joints.joint_count)
    ab = np.stack([model.joints.joint_a, np.where(model.joints.joint_b < 0, n,
                                                  model.joints.joint_b)], axis=1)
    inv_mass = np.concatenate([model.body_inv_mass, [0.0]])
    r = js.rows(model.joints, ids, ab, np.concatenate([x, np.zeros((1, 3))]), rot, inv_mass,
                inv_inertia, DT / 8)
    momentum = np.concatenate([state.body_P, np.zeros((1, 3))])
    group = None if anchored else np.concatenate([np.zeros(n, np.int64), [-1]])
    return r, n + 1, momentum, inv_mass, group


def test_the_direct_chain_solve_equals_conjugate_gradients():
    """The joints of a hanging 12-link chain (and a free-floating one, whose angular momentum
    rows couple it whole) solved directly along the chain and by conjugate gradients: the
    same moves to 1e-5 relative (the iterations stop at a residual of 1e-6)."""
    from physanim.core.rigid import joint_solver as js

    for anchored in (True, False):
        r, count, momentum, inv_mass, group = _disturbed_chain(anchored)
        assert r.paths is not None and len(r.paths) == 1
        direct = js.displacement(r, count, momentum, inv_mass, group)
        r.paths = None
        iterative = js.displacement(r, count, momentum, inv_mass, group)
        assert np.abs(direct - iterative).max() < 1e-5 * np.abs(iterative).max()
        assert np.abs(direct).max() > 1e-5  # it moved something


def test_the_groups_columns_are_the_systems_own():
    """The columns of the angular-momentum rows of groups of free joined bodies, built all at
    once, equal the system applied to each of their unit vectors — for one group, and for the
    links split into three groups at random (a joint's two sides in different groups)."""
    from physanim.core.rigid import joint_solver as js

    r, count, momentum, inv_mass, group = _disturbed_chain(False)
    rng = np.random.default_rng(7)
    for labels in (group, np.concatenate([rng.integers(0, 3, count - 1), [-1]])):
        use = np.concatenate([r.holds, rng.random((len(r), 4)) < 0.5], axis=1)
        op = js._Rows(r, count, use, None, momentum, inv_mass, labels)
        unit = np.eye(3 * op.groups)
        expected = np.array([op(op.pack(np.zeros(use.shape), e)) for e in unit]).T
        columns = op.group_columns()
        assert columns.shape == expected.shape and op.groups == len(np.unique(labels)) - 1
        np.testing.assert_allclose(columns, expected, rtol=0, atol=1e-12 * np.abs(
            expected).max())
        assert np.abs(columns[:len(r) * js.ROWS]).max() > 0.0


def test_keyed_joint_values_change_the_motor_limit_and_breaking_frame_by_frame():
    """The joints' limits, motors, springs and breaking are read every frame (keyframable in
    Blender): the door's motor target keyed from 1 to -1 rad/s at 0.5 s turns it back at the
    new speed (within 2 %); a limit at -0.5 rad keyed on at 1 s catches it there; and a hook
    whose breaking force is keyed down below the weight it carries lets go on that frame."""
    model, solver, state = door()
    base = JointSettings("Hinge", "HINGE", 0, matrix=joint_frame((0.0, 0.0, 1.0)),
                         use_motor=True, motor_velocity=1.0, motor_max=50.0, lower=-0.5,
                         upper=0.5)
    speeds, angles = [], []

    def world_w(s):
        r = quat.to_matrix(s.body_q)[0]
        return (r @ np.linalg.solve(model.body_inertia[0], r.T @ s.body_L[0]))[2]

    for f in range(int(2.5 / DT)):
        t = f * DT
        keyed = replace(base, motor_velocity=1.0 if t < 0.5 else -1.0, use_limits=t >= 1.0)
        solver.advance(state, RigidFrameInputs(f, t, DT, (0.0, 0.0, -G),
                                               joint_settings=[keyed]))
        speeds.append(world_w(state))
        angles.append(hinge_angle(state))
    assert speeds[int(0.45 / DT)] == pytest.approx(1.0, rel=0.02)
    assert speeds[int(0.95 / DT)] == pytest.approx(-1.0, rel=0.02)
    caught = angles[int(1.0 / DT):]
    assert min(caught) > -0.5 - 1e-3 and caught[-1] == pytest.approx(-0.5, abs=1e-2)

    m = 3.0
    hook = JointSettings("Hook", "BALL", 0, break_force=2.0 * m * G)
    _, solver, state = build([box("Box", (0.1, 0.1, 0.1), (0.0, 0.0, -0.1), mass=m)], [hook])
    for f in range(24):
        keyed = replace(hook, break_force=(2.0 if f < 12 else 0.5) * m * G)
        report = solver.advance(state, RigidFrameInputs(f, f * DT, DT, (0.0, 0.0, -G),
                                                        joint_settings=[keyed]))
        assert report.broken == (["Hook"] if f == 12 else [])
    assert state.joints.joint_broken_frame[0] == 12
    with pytest.raises(PhysanimError, match="type changed"):
        solver.advance(state, RigidFrameInputs(24, 1.0, DT, joint_settings=[
            replace(hook, kind="FIXED")]))


def test_a_spring_joint_holds_a_box_as_a_damped_spring():
    """A 2 kg box on a spring joint (k = 50 N/m, zero rest length) at its centre, to the world,
    released at the joint: it bounces about the static sag m g / k (0.39 m) with the period
    2 pi sqrt(m / k) (1.26 s; within 2 %: the soft step is implicit, omega h = 0.03); with
    damping d = 2 zeta sqrt(k m) at zeta = 0.2 each swing's amplitude falls by
    exp(-zeta omega T_d), to first order in the sub-step (16 % off at 8 sub-steps, 4 % at
    32)."""
    m, k = 2.0, 50.0
    spring = JointSettings("Bungee", "SPRING", 0, stiffness=k)
    _, solver, state = build([box("Box", (0.1, 0.1, 0.1), (0.0, 0.0, 0.0), mass=m,
                                  linear_damping=0.0, angular_damping=0.0)], [spring])
    z = []
    run(solver, state, int(6 / DT), each=lambda f, s: z.append(s.body_x[0, 2]))
    z = np.array(z) + m * G / k
    t = np.arange(1, len(z) + 1) * DT
    up = np.nonzero((z[:-1] < 0.0) & (z[1:] >= 0.0))[0]
    crossings = t[up] - z[up] * DT / (z[up + 1] - z[up])
    assert np.mean(np.diff(crossings)) == pytest.approx(2 * math.pi * math.sqrt(m / k),
                                                       rel=0.02)
    # undamped: back up towards the pivot after a period, losing no more than backward Euler
    # would at the sub-step h (the soft rows are implicit): (1 + (omega h)^2)^(-T / 2h) = 0.92
    # of the amplitude (measured 0.976)
    h, period = DT / solver.substeps, 2 * math.pi * math.sqrt(m / k)
    first = np.max(z[:int(1.5 * period / DT)]) / (m * G / k)
    assert (1 + (k / m) * h * h) ** (-period / (2 * h)) < first <= 1.0

    zeta = 0.2
    omega = math.sqrt(k / m)
    exact = math.exp(-zeta * omega * 2 * math.pi / (omega * math.sqrt(1 - zeta ** 2)))
    errors = []
    for substeps in (8, 32):  # the soft step is first order: the error falls 4-fold
        b = RigidBodyBuilder()
        b.add_body(box("Box", (0.1, 0.1, 0.1), (0.0, 0.0, 0.0), mass=m, linear_damping=0.0))
        b.add_joint(JointSettings("Bungee", "SPRING", 0, stiffness=k,
                                  damping=2 * zeta * math.sqrt(k * m)))
        model = b.finalize()
        solver, state = RigidBodySolver(model, substeps), model.state()
        heights: list = []
        run(solver, state, int(3 / DT), each=lambda f, s, out=heights: out.append(
            s.body_x[0, 2]))
        z = np.array(heights) + m * G / k
        peaks = [z[i] for i in range(1, len(z) - 1) if z[i] > z[i - 1] and z[i] >= z[i + 1]]
        errors.append(abs(peaks[1] / peaks[0] - exact) / exact)
    assert errors[1] < 0.06 and 3.0 < errors[0] / errors[1] < 5.0
    with pytest.raises(PhysanimError, match="needs a stiffness or a damping"):
        JointSettings("Slack", "SPRING", 0)


@pytest.mark.parametrize("case", ["door on two hinges", "door on two hinges, motor",
                                  "door on two hinges at one pivot", "door on a hinge and a slider",
                                  "two links on two hinges", "hinge and fixed joint"])
def test_redundant_joints_hold_without_blowing_up(case):
    """Joints that hold the same freedoms twice (a door hung on two hinges on one axis, or at
    one pivot, or by a hinge and a slider there; two links joined by two hinges on one axis,
    or by a hinge and a fixed joint) make the joints' system singular: it is solved by
    conjugate gradients instead of the chain solve, and the door swings about its hinges' axis
    (driven at its motor's speed; held still by the slider), the links stay joined."""
    if case.startswith("door"):
        kw = dict(use_motor=True, motor_velocity=1.0, motor_max=50.0) if "motor" in case \
            else {}
        bodies = [box("Door", (0.4, 0.02, 1.0), (0.4, 0.0, 1.0), mass=20.0,
                      angular_velocity=(0.0, 0.0, 0.5), angular_damping=0.0)]
        low, high = (1.0, 1.0) if ("one pivot" in case or "slider" in case) else (0.2, 1.8)
        joints = [JointSettings("Low", "HINGE", 0, matrix=joint_frame((0.0, 0.0, low)), **kw),
                  JointSettings("High", "SLIDER" if "slider" in case else "HINGE", 0,
                                matrix=joint_frame((0.0, 0.0, high)))]
    else:
        bodies = [box(f"L{i}", (0.15, 0.03, 0.03), ((i + 0.5) * 0.3, 0.0, 2.0),
                      angular_velocity=(0.0, 1.0, 0.3)) for i in range(2)]
        second = "FIXED" if "fixed" in case else "HINGE"
        joints = [JointSettings("A", "HINGE", 0, 1, matrix=joint_frame((0.3, 0, 2), (0, 1, 0))),
                  JointSettings("B", second, 0, 1, matrix=joint_frame((0.3, 0, 2), (0, 1, 0)))]
    _, solver, state = build(bodies, joints)
    run(solver, state, 48)
    rot = quat.to_matrix(state.body_q)
    assert np.isfinite(state.body_x).all() and np.isfinite(state.body_L).all()
    if case.startswith("door"):
        # the hinge edge stays on the axis, the door upright, and it turned
        edge = state.body_x[0] + rot[0] @ np.array([-0.4, 0.0, 0.0])
        assert np.abs(edge[:2]).max() < 1e-5 and rot[0][2, 2] > 1 - 1e-6
        w = rot[0] @ np.linalg.solve(solver.model.body_inertia[0],
                                     rot[0].T @ state.body_L[0])
        assert np.abs(w[:2]).max() < 1e-3
        # a slider holds the turn a hinge leaves free: that door is held still
        assert abs(w[2]) < 1e-6 if "slider" in case else abs(w[2]) > 0.1
        if "motor" in case:
            assert w[2] == pytest.approx(1.0, rel=0.02)
    else:  # the shared pivot: the same point of both links
        pivot = [state.body_x[i] + rot[i] @ np.array([0.15 - 0.3 * i, 0.0, 0.0])
                 for i in range(2)]
        assert np.abs(pivot[0] - pivot[1]).max() < 1e-6
        assert np.abs(state.body_x[:, 2] - 2.0).max() > 0.5  # they fell (freely, joined)
