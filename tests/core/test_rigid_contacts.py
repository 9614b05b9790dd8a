"""Rigid-body contacts against closed forms and measurable criteria: bounce apex ratios, friction
on a slope, coming to rest, stacks, momentum, exchange of velocities, no tunnelling."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from physanim.core.contact import ColliderFrame
from physanim.core.rigid import quaternion as quat
from physanim.core.rigid import collide
from physanim.core.rigid.collide import SPECULATIVE
from physanim.tests.core.rigid_helpers import DT, box, ground, run, sphere, world


def _apexes(heights: np.ndarray) -> list[float]:
    """Local maxima of a height track (apexes between bounces)."""
    h = heights
    return [h[i] for i in range(1, len(h) - 1) if h[i] > h[i - 1] and h[i] >= h[i + 1]]


@pytest.mark.parametrize("e", [0.5, 0.8])
def test_ball_bounce_apex_ratio_is_restitution_squared(e):
    r = 0.1
    model, solver, state = world(sphere("Ball", r, (0.0, 0.0, 1.0 + r), restitution=e,
                                        linear_damping=0.0, angular_damping=0.0), substeps=16)
    heights = []
    run(solver, state, 96, colliders=[ground(restitution=1.0)],  # combined: e * 1
        each=lambda f, s: heights.append(s.body_x[0, 2] - r))
    # apex heights sampled per frame: refine each by the parabola through the top 3 samples
    apexes = _apexes(np.array(heights))
    assert len(apexes) >= 2, heights
    first = 1.0
    ratio = apexes[0] / first
    assert abs(ratio - e * e) <= 0.03, (apexes, e * e)
    if len(apexes) > 1 and apexes[0] > 0.05:
        assert abs(apexes[1] / apexes[0] - e * e) <= 0.03 + 0.02 / apexes[0], apexes


def test_box_dropped_on_the_ground_comes_to_rest_within_a_second():
    model, solver, state = world(box("Box", (0.5, 0.5, 0.5), (0.0, 0.0, 1.5)))
    speeds, heights = [], []
    run(solver, state, int(3.0 / DT), colliders=[ground()],
        each=lambda f, s: (speeds.append(np.linalg.norm(s.body_P[0]) / model.body_mass[0]),
                           heights.append(s.body_x[0, 2])))
    after = int(1.0 / DT) + int(0.55 / DT)  # it lands after 0.45 s; at rest a second later
    assert max(speeds[after:]) < 1e-3, speeds[after:]
    assert np.ptp(heights[after:]) < 1e-4  # no jitter
    assert abs(heights[-1] - 0.5) < 5e-3  # resting on its face, at most 5 mm into the ground


def test_a_body_never_collides_with_a_collider_of_its_own_name():
    """A collider named as a body is that body's own object tagged as a collider too (an
    animated one's collider follows it): the body takes no contact with it. A 1 m box whose
    still copy sits where it starts falls onto the ground as it does without the copy."""
    def fall(colliders):
        model, solver, state = world(box("Box", (0.5, 0.5, 0.5), (0.0, 0.0, 1.5)))
        run(solver, state, 24, colliders=colliders)
        return state.body_x.copy(), state.body_q.copy()

    m = np.eye(4)
    m[:3, :3] *= 0.5
    m[:3, 3] = (0.0, 0.0, 1.5)
    copy = ColliderFrame("Box", "BOX", m, m, 0.0, 0.5)
    alone, with_copy = fall([ground()]), fall([ground(), copy])
    assert alone[0][0, 2] < 0.51  # it fell
    assert np.array_equal(alone[0], with_copy[0]) and np.array_equal(alone[1], with_copy[1])


@pytest.mark.parametrize("mu, tilt", [(0.6, math.radians(20.0)), (0.2, math.radians(30.0))])
def test_box_on_a_slope_sticks_or_slides_by_coulomb(mu, tilt):
    """mu > tan(theta): stays (drift < 1 mm in 5 s); mu < tan(theta): slides with
    a = g (sin(theta) - mu cos(theta))."""
    n = np.array([0.0, -math.sin(tilt), math.cos(tilt)])  # the slope's normal
    down = np.array([0.0, -math.cos(tilt), -math.sin(tilt)])  # down the slope
    half = 0.25
    from physanim.core.rigid import quaternion as quat
    q = quat.from_rotation_vector(np.array([[tilt, 0.0, 0.0]]))[0]
    body = box("Box", (half, half, half), tuple(n * (half + 1e-3)), friction=mu,
               orientation=tuple(q), linear_damping=0.0, angular_damping=0.0)
    model, solver, state = world(body)
    track = []
    run(solver, state, int(5.0 / DT), colliders=[ground(friction=mu, tilt=tilt)],
        each=lambda f, s: track.append(s.body_x[0].copy()))
    track = np.array(track)
    along = track @ down
    settle = int(0.5 / DT)
    if mu > math.tan(tilt):
        assert abs(along[-1] - along[settle]) < 1e-3
    else:
        t = np.arange(len(along)) * DT
        a_fit = np.polyfit(t[settle:], along[settle:], 2)[0] * 2.0
        a_true = 9.81 * (math.sin(tilt) - mu * math.cos(tilt))
        assert abs(a_fit - a_true) <= 0.02 * a_true, (a_fit, a_true)


@pytest.mark.parametrize("count", [10, 20])
def test_box_stack_stands(count):
    size = 0.5
    boxes = [box(f"B{k}", (size, size, size), (0.0, 0.0, size + 2 * size * k)) for k in range(count)]
    model, solver, state = world(*boxes)
    tops = []
    run(solver, state, int(10.0 / DT), colliders=[ground()],
        each=lambda f, s: tops.append(s.body_x[-1].copy()))
    tops = np.array(tops)
    second = int(1.0 / DT)
    drift = np.linalg.norm(tops[second:] - tops[second], axis=1).max()
    assert drift < 1e-3, drift
    assert abs(tops[-1, 2] - (2 * count - 1) * size) < 0.01 * count  # still a stack


def test_collisions_away_from_colliders_conserve_momentum():
    rng = np.random.default_rng(3)
    bodies = []
    for k in range(12):
        x = rng.uniform(-1.0, 1.0, 3)
        v = -x * 4.0 + rng.normal(size=3)
        w = rng.normal(size=3) * 3.0
        make = box if k % 2 else sphere
        size = (0.2, 0.3, 0.25) if k % 2 else 0.25
        bodies.append(make(f"b{k}", size, tuple(x * 3.0), mass=1.0 + k, velocity=tuple(v),
                           angular_velocity=tuple(w), linear_damping=0.0, angular_damping=0.0,
                           restitution=0.3))
    model, solver, state = world(*bodies)

    def momenta(s):
        P = s.body_P.sum(axis=0)
        L = (np.cross(s.body_x, s.body_P) + s.body_L).sum(axis=0)
        return P, L

    P0, L0 = momenta(state)
    reports = run(solver, state, 48, gravity=(0.0, 0.0, 0.0))
    assert sum(r.contacts for r in reports) > 0  # they did collide
    P1, L1 = momenta(state)
    scale_p = np.abs(state.body_P).sum()
    scale_l = np.abs(np.cross(state.body_x, state.body_P)).sum() + np.abs(state.body_L).sum()
    assert np.linalg.norm(P1 - P0) <= 1e-9 * scale_p
    assert np.linalg.norm(L1 - L0) <= 1e-9 * scale_l


def test_equal_spheres_head_on_with_restitution_one_exchange_velocities():
    a = sphere("A", 0.2, (-1.0, 0.0, 0.0), velocity=(3.0, 0.0, 0.0), restitution=1.0,
               linear_damping=0.0, angular_damping=0.0)
    b = sphere("B", 0.2, (1.0, 0.0, 0.0), restitution=1.0, linear_damping=0.0,
               angular_damping=0.0)
    model, solver, state = world(a, b)
    run(solver, state, 24, gravity=(0.0, 0.0, 0.0))
    np.testing.assert_allclose(state.body_P[0], [0.0, 0.0, 0.0], atol=0.03)
    np.testing.assert_allclose(state.body_P[1], [3.0, 0.0, 0.0], atol=0.03)


def test_bodies_overlapping_at_the_start_separate_without_explosion():
    """A careless pile: six 1 m boxes each sunk 20 cm into the one below (and the ground)."""
    boxes = [box(f"B{k}", (0.5, 0.5, 0.5), (0.05 * k, 0.02 * k, 0.3 + 0.8 * k)) for k in range(6)]
    model, solver, state = world(*boxes)
    fastest = []
    run(solver, state, 72, colliders=[ground()],
        each=lambda f, s: fastest.append(np.linalg.norm(s.body_P, axis=1).max()))
    assert max(fastest) <= 5.0
    assert max(fastest[-12:]) < 0.05  # and they settle


def test_small_fast_box_never_passes_a_thin_wall():
    """A 10 cm box at 100 m/s against a 1 cm wall (a Box collider 5 mm half thick)."""
    wall = np.diag([0.005, 2.0, 2.0, 1.0])
    wall[:3, 3] = (2.0, 0.0, 0.0)
    collider = ColliderFrame("Wall", "BOX", wall, wall, 0.0, 0.3)
    body = box("Bullet", (0.05, 0.05, 0.05), (0.0, 0.0, 0.0), velocity=(100.0, 0.0, 0.0))
    model, solver, state = world(body)
    xs = []
    run(solver, state, 24, colliders=[collider], gravity=(0.0, 0.0, 0.0),
        each=lambda f, s: xs.append(s.body_x[0, 0]))
    assert max(xs) < 2.0 - 0.005 - 0.05 + 0.005, max(xs)


def test_hull_rocks_fall_onto_a_box_and_the_ground_and_rest():
    """Convex hulls (random rocks) against a box body, a sphere and the ground: no overlap
    beyond a centimetre at any frame, the rocks and the table at rest in the end."""
    from physanim.core.collision.hull import convex_hull
    from physanim.core.rigid.mass import polyhedron_mass
    from physanim.core.rigid.model import RigidBodySettings

    rng = np.random.default_rng(5)
    bodies = [box("Table", (1.0, 1.0, 0.25), (0.0, 0.0, 0.25), mass=2000.0),
              sphere("Ball", 0.3, (1.5, 0.2, 0.3), mass=113.0)]  # all of density 1000
    for k in range(4):
        cloud = rng.normal(size=(40, 3)) * (0.3, 0.25, 0.2)
        hull = convex_hull(cloud)
        verts = hull.points[hull.vertices]
        bodies.append(RigidBodySettings(
            f"Rock{k}", "HULL", polyhedron_mass(hull.points, hull.triangles, density=1000.0),
            hull=verts, position=(0.6 * k - 0.9, 0.1 * k, 1.5 + 0.7 * k)))
    model, solver, state = world(*bodies)
    reports = run(solver, state, int(5.0 / DT), colliders=[ground()])
    assert max(r.overlap for r in reports) < 0.01
    speeds = np.linalg.norm(state.body_P, axis=1) / model.body_mass
    rest = [0, *range(2, model.body_count)]  # the ball may still roll: nothing stops it
    assert speeds[rest].max() < 0.01, speeds
    assert abs(state.body_x[1, 2] - 0.3) < 0.01  # the ball is on the ground


def test_resting_bodies_fall_asleep_and_wake_when_hit():
    """A box at rest sleeps (no motion at all, no cost); a ball rolled into it wakes it."""
    resting = box("Box", (0.5, 0.5, 0.5), (0.0, 0.0, 0.5))
    ball = sphere("Ball", 0.3, (-8.0, 0.0, 0.3), velocity=(0.0, 0.0, 0.0))
    model, solver, state = world(resting, ball)
    reports = run(solver, state, 36, colliders=[ground()])
    assert reports[-1].sleeping == 2  # both at rest for half a second
    x0 = state.body_x[0].copy()
    run(solver, state, 24, colliders=[ground()], start=36)
    assert np.array_equal(state.body_x[0], x0)  # asleep: exactly still
    state.body_asleep[1] = False  # the ball is thrown at the box
    state.body_P[1] = (model.body_mass[1] * 12.0, 0.0, 0.0)
    reports = run(solver, state, 36, colliders=[ground()], start=60)
    assert np.linalg.norm(state.body_x[0] - x0) > 0.05  # woken and pushed
    assert not state.body_asleep[0] or reports[-1].sleeping >= 1


def test_kinematic_body_follows_its_path_and_pushes_a_dynamic_one():
    """An animated (kinematic) paddle sweeps along x at 2 m/s and pushes a resting box ahead of
    it; the paddle itself is not pushed back."""
    from physanim.core.rigid.solver import RigidFrameInputs

    paddle = box("Paddle", (0.1, 1.0, 0.5), (-1.0, 0.0, 0.5), kinematic=True)
    target = box("Box", (0.25, 0.25, 0.25), (0.0, 0.0, 0.25))
    model, solver, state = world(paddle, target)

    def at(t):
        m = np.eye(4)
        m[:3, 3] = (-1.0 + 2.0 * t, 0.0, 0.5)
        return m

    for f in range(36):
        t0, t1 = f * DT, (f + 1) * DT
        solver.advance(state, RigidFrameInputs(f, t0, DT, (0.0, 0.0, -9.81), [ground()],
                                               {0: np.stack([at(t0), at(t1)])}))
    paddle_x = state.origins(model)[0, 0]
    assert paddle_x == pytest.approx(-1.0 + 2.0 * 36 * DT, abs=1e-9)  # on its path exactly
    assert state.body_x[1, 0] > paddle_x + 0.1 + 0.25 - 0.01  # pushed ahead, not overlapped
    assert state.body_x[1, 0] > 0.5  # it moved with the paddle


@pytest.mark.parametrize("friction", [0.3, 0.8])
def test_a_domino_tipped_over_lands_flat_without_sinking(friction):
    """A 5 x 25 x 50 cm box tipped over falls onto its face at speed (its top edge near
    4 m/s): the corners it lands on are found before it lands — whether its foot holds
    (friction 0.8) or slides out (0.3, a collider's default) — and it ends flat, at rest."""
    half = np.array([0.025, 0.125, 0.25])
    model, solver, state = world(box("Domino", tuple(half), (0.0, 0.0, 0.25),
                                     angular_velocity=(0.0, 2.5, 0.0)))
    lows = []

    def low(f, s):
        rot = quat.to_matrix(s.body_q)[0]
        lows.append(s.body_x[0, 2] - np.abs(rot[2]) @ half)  # deepest corner's height

    run(solver, state, 48, colliders=[ground(friction=friction)], each=low)
    assert min(lows) > -0.002, min(lows)
    up = quat.to_matrix(state.body_q)[0][:, 2]
    assert abs(up[2]) < 0.05  # lying on its face
    assert abs(state.body_x[0, 2] - half[0]) < 0.002
    assert np.linalg.norm(state.body_P) < 1e-3


def _path_inputs(f, colliders, paths):
    from physanim.core.rigid.solver import RigidFrameInputs

    return RigidFrameInputs(f, f * DT, DT, (0.0, 0.0, -9.81), colliders, paths)


def test_a_body_let_go_by_its_animation_flies_off_with_the_paths_velocity():
    """A box carried along a straight path at (2, 0, 3) m/s is let go at frame 12 (its path
    ends: it is simulated from then on): it leaves with the path's velocity and flies as a
    projectile from where it was let go (free flight is exact for this integrator up to the
    rounding of its sub-steps)."""
    crate = box("Crate", (0.1, 0.1, 0.1), (0.0, 0.0, 1.0), kinematic=True, linear_damping=0.0)
    model, solver, state = world(crate)
    speed = np.array([2.0, 0.0, 3.0])

    def at(t):
        m = np.eye(4)
        m[:3, 3] = np.array([0.0, 0.0, 1.0]) + speed * t
        return m

    release = 12
    for f in range(36):
        paths = {0: np.stack([at(f * DT), at((f + 1) * DT)])} if f < release else {}
        solver.advance(state, _path_inputs(f, [], paths))
        if f == release - 1:
            np.testing.assert_allclose(state.body_P[0], speed * model.body_mass[0], atol=1e-9)
    t = (36 - release) * DT
    start = np.array([0.0, 0.0, 1.0]) + speed * release * DT
    expected = start + speed * t + 0.5 * np.array([0.0, 0.0, -9.81]) * t ** 2
    h = DT / solver.substeps
    # sub-stepped symplectic Euler: x_n = x_0 + v_0 t + g t (t + h) / 2
    np.testing.assert_allclose(state.body_x[0], expected + [0, 0, -9.81 * t * h / 2], atol=1e-9)
    np.testing.assert_allclose(state.body_P[0] / model.body_mass[0],
                               speed + [0.0, 0.0, -9.81 * t], atol=1e-9)


def test_a_simulated_body_that_joins_a_path_follows_it_and_pushes():
    """A box falls freely for 6 frames, then follows its animation (a path sweeping along x)
    and, on it, pushes a resting box as any animated body does."""
    paddle = box("Paddle", (0.1, 1.0, 0.5), (-1.0, 0.0, 2.0))
    target = box("Box", (0.25, 0.25, 0.25), (0.0, 0.0, 0.25))
    model, solver, state = world(paddle, target)

    def at(t):
        m = np.eye(4)
        m[:3, 3] = (-1.0 + 2.0 * (t - 6 * DT), 0.0, 0.5)
        return m

    for f in range(36):
        paths = {0: np.stack([at(f * DT), at((f + 1) * DT)])} if f >= 6 else {}
        solver.advance(state, _path_inputs(f, [ground()], paths))
        if f == 5:
            assert state.body_x[0, 2] < 2.0 - 0.3  # it fell
    assert state.origins(model)[0, 0] == pytest.approx(-1.0 + 2.0 * 30 * DT, abs=1e-9)
    assert state.body_x[1, 0] > state.origins(model)[0, 0] + 0.1 + 0.25 - 0.01


def test_boxes_falling_side_by_side_make_no_contacts():
    """A column of boxes 30 cm apart falling together never approach each other: no contact
    points between them (a margin from each body's own speed, 10 m/s after a second, would
    have them all in contact), and they fall as free bodies."""
    boxes = [box(f"B{k}", (0.25, 0.25, 0.25), (0.0, 0.0, 10.0 + 0.8 * k)) for k in range(4)]
    model, solver, state = world(*boxes)
    reports = run(solver, state, 24)
    assert [r.contacts for r in reports] == [0] * 24
    assert np.ptp(state.body_P[:, 2]) == 0.0 and np.ptp(np.diff(state.body_x[:, 2])) < 1e-12


def test_a_falling_column_lands_into_a_stack_without_sinking():
    """The same column dropped onto the ground: each box stops on the one below as it lands
    (the lower one stopped by the ground within the search interval), never sinking more than a
    centimetre into it, and the stack stands."""
    boxes = [box(f"C{k}", (0.25, 0.25, 0.25), (0.0, 0.0, 1.0 + 0.8 * k)) for k in range(6)]
    model, solver, state = world(*boxes)
    spacing = []
    run(solver, state, 72, colliders=[ground()],
        each=lambda f, s: spacing.append(np.diff(np.sort(s.body_x[:, 2])).min()))
    assert min(spacing) > 0.5 - 0.01
    assert np.abs(state.body_P).max() < 1e-3 and np.abs(state.body_x[:, :2]).max() < 1e-3


def test_candidate_pairs_kept_between_searches_change_nothing_and_save_searches():
    """A heap of 27 turned boxes dropped onto the ground: reading the broad phase's pairs from
    the last search while every swept box stays within the one it was found for gives the
    same motion to the bit as searching every time, with fewer searches."""
    rng = np.random.default_rng(3)
    boxes = [box(f"H{k}", (0.25, 0.25, 0.25),
                 (0.8 * (k % 3), 0.8 * (k // 3 % 3), 0.6 + 0.8 * (k // 9)),
                 orientation=tuple(quat.normalized(np.array([1.0, *rng.uniform(-0.2, 0.2, 3)]))))
             for k in range(27)]
    states, searches = [], []
    for keep in (True, False):
        model, solver, state = world(*boxes)
        if not keep:
            solver._pairs = None
        calls = []
        if keep:
            find = solver._pairs.find
            solver._pairs.find = lambda lo, hi, calls=calls, find=find: \
                calls.append(1) or find(lo, hi)
        run(solver, state, 48, colliders=[ground()])
        states.append((state.body_x.copy(), state.body_q.copy()))
        searches.append(len(calls))
    assert np.array_equal(states[0][0], states[1][0]) and np.array_equal(states[0][1], states[1][1])
    assert 0 < searches[0] < 48  # (up to 4 a frame at the default 8 sub-steps; 12 measured)


def test_boxes_corner_to_corner_beyond_the_margin_make_no_contacts():
    """Two cubes at rest (no gravity) 1.5 cm apart along each axis, their nearest corners
    2.6 cm apart: further than the 2 cm speculative margin, so no contact point (separating
    axes along the faces alone see them 1.5 cm apart)."""
    d = 0.5 + 0.015
    model, solver, state = world(box("A", (0.25, 0.25, 0.25), (0.0, 0.0, 0.0)),
                                 box("B", (0.25, 0.25, 0.25), (d, d, d)))
    assert math.sqrt(3.0) * 0.015 > SPECULATIVE
    reports = run(solver, state, 2, gravity=(0.0, 0.0, 0.0))
    assert [r.contacts for r in reports] == [0, 0]


def test_a_pairs_margin_bounds_how_far_the_two_can_approach_within_the_frame():
    """For random pairs (dynamic, kinematic, sleeping, colliders) moving at constant velocity
    and spin, the dynamic ones falling: within the frame no point of one comes nearer the
    other by more than the pair's closing distance (each point moves with its centre, and
    turning moves it at most |w| times the bound radius); and a body let fall from rest onto
    one that does not fall closes by the fall, 0.5 g dt^2."""
    rng = np.random.default_rng(11)
    n, dt = 400, DT
    g = np.array([0.0, 0.0, -9.81])
    bodies = SimpleNamespace(v=rng.normal(size=(n, 3)) * rng.choice([0.0, 0.1, 3.0], (n, 1)),
                             w=rng.normal(size=(n, 3)) * rng.choice([0.0, 2.0], (n, 1)),
                             bound=rng.uniform(0.05, 1.0, n), dynamic=rng.random(n) < 0.6)
    i, j = rng.integers(0, n, (2, 2000))
    closing = collide._closing(bodies, i, j, dt, dt / 4, g)
    t = np.linspace(0.0, dt, 33)[:, None, None]

    def moved(k):  # each centre's displacement over the frame
        return bodies.v[k] * t + np.where(bodies.dynamic[k, None], 0.5 * g * t ** 2, 0.0)
    spin = (np.linalg.norm(bodies.w[i], axis=1) * bodies.bound[i]
            + np.linalg.norm(bodies.w[j], axis=1) * bodies.bound[j]) * t[..., 0]
    assert np.all(np.linalg.norm(moved(j) - moved(i), axis=2) + spin <= closing + 1e-12)
    still = (bodies.dynamic[i] != bodies.dynamic[j]) & \
        (np.abs(bodies.v[i] - bodies.v[j]).sum(axis=1) == 0.0) & \
        (np.abs(bodies.w[i]).sum(axis=1) + np.abs(bodies.w[j]).sum(axis=1) == 0.0)
    assert still.sum() > 10
    assert np.allclose(closing[still], 0.5 * 9.81 * dt ** 2, rtol=1e-12)
