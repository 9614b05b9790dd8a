"""Timing (core/controls/timing.py): the time map between frames and simulated time, the poses
the world samples between sub-steps, and the emission window under a time scale."""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.controls.timing import TimeMap, window_active
from physanim.core.particles import (EmitterFrame, EmitterSettings, ParticleDrive, ParticleSolver,
                                     ParticleSystem)
from physanim.core.particles.model import ParticleState
from physanim.core.rigid.model import RigidBodyState
from physanim.core.springs.model import SpringMeshState
from physanim.core.world import World, WorldFrame
from physanim.tests.core.helpers import particle_model, place

DT = 1.0 / 24.0


def test_scale_one_is_the_identity_to_the_bit():
    clock = TimeMap.constant(-3, 500)
    frames = np.arange(-3, 501)
    assert clock.identity
    assert (clock.tau(frames) == frames).all()
    assert all(clock.frame(float(f)) == f and isinstance(clock.frame(float(f)), int)
               for f in frames)
    assert clock.frames_in(10.0, 10, 500) == [(11, 1.0)]
    assert clock.simulation_frames() == 503


def test_trapezoid_rule_and_its_inverse():
    """tau(f + 1) - tau(f) = (s(f) + s(f + 1)) / 2; exact for a linear ramp, whose integral is
    known; frame() inverts tau() everywhere, beyond the ends too."""
    scale = np.linspace(1.0, 0.1, 31)  # frames 5 .. 35
    clock = TimeMap(5, scale)
    assert clock.tau(35) - 5 == pytest.approx(30 * (1.0 + 0.1) / 2, rel=1e-12)
    for f in np.linspace(-10.0, 60.0, 701):
        assert clock.frame(clock.tau(f)) == pytest.approx(f, abs=1e-9)
    assert clock.tau(3.0) == pytest.approx(5.0 - 2.0 * 1.0)  # before: the first scale
    assert clock.tau(40.0) == pytest.approx(clock.tau(35) + 5 * 0.1)  # after: the last


def test_frames_shown_by_each_simulation_frame_cover_every_frame_once():
    rng = np.random.default_rng(4)
    clock = TimeMap(1, rng.uniform(0.05, 3.0, 80))
    shown, tau, last = [], 1, 1
    while last < 80:
        got = clock.frames_in(tau, last, 80)
        for f, w in got:
            assert 0.0 < w <= 1.0
            assert clock.tau(f) == pytest.approx(tau + w, abs=1e-12)
        shown += [f for f, _ in got]
        last = got[-1][0] if got else last
        tau += 1
    assert shown == list(range(2, 81))
    assert tau - 1 == clock.simulation_frames()


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), 101.0])
def test_a_scale_out_of_range_names_the_frame(bad):
    scale = np.ones(10)
    scale[6] = bad
    with pytest.raises(ValueError, match="frame 13"):
        TimeMap(7, scale)


def test_emission_window_spans_its_simulated_time():
    """A window of frames gives births in the simulation frames it spans (a rate is births
    per simulated frame: at double speed a frame holds two); in slow motion a one-frame burst
    still falls in exactly one simulation frame, never none or two. At scale 1 the rule is
    the old first <= f <= last."""
    for scale in (0.01, 0.25, 0.3, 1.0, 2.0, 7.5):
        clock = TimeMap.constant(-10, 200, scale)
        for first, last in ((1, 1), (4, 4), (3, 9)):
            active = [window_active(first, last, clock.frame(t), clock.frame(t + 1))
                      for t in np.arange(clock.tau(-10) - 2, clock.tau(200) + 1)]
            expected = max(1, int(round((last - first + 1) * scale)))
            assert abs(sum(active) - expected) <= 1, (scale, first, last)
            if first == last and scale <= 1.0:
                assert sum(active) == 1
    assert [window_active(3, 5, f - 1, f) for f in range(0, 9)] == [
        3 <= f <= 5 for f in range(0, 9)]


def test_particle_pose_between_substeps():
    """Particles in both poses on the line between; a newborn appears once born, back along
    its velocity; one dying shows until its life ends."""
    a = ParticleState.empty(1.0, [np.random.default_rng(0)])
    place(a, [[0, 0, 0], [1, 0, 0]], [[1, 0, 0], [0, 0, 1]], life=1.0)
    a.particle_age[:] = [0.2, 0.95]  # the second dies at t = 1.05
    b = a.pose()
    b.t = 1.1
    b.keep(np.array([True, False]))
    b.particle_x[0] = [0.1, 0.0, 0.0]
    b.particle_age[0] = 0.3
    b.append(0, np.array([[5.0, 0, 0]]), np.array([[2.0, 0, 0]]), np.ones(1), np.array([0.04]),
             np.ones(1), np.ones(1))  # born at t = 1.06
    early = ParticleState.between(a, b, 0.3)  # t = 1.03
    assert early.t == pytest.approx(1.03)
    assert list(early.particle_id) == [0, 1]
    assert early.particle_x[0] == pytest.approx([0.03, 0, 0])
    assert early.particle_x[1] == pytest.approx([1.0, 0, 0.03])
    assert early.particle_age == pytest.approx([0.23, 0.98])
    late = ParticleState.between(a, b, 0.8)  # t = 1.08: the second died, the third was born
    assert list(late.particle_id) == [0, 2]
    assert late.particle_x[1] == pytest.approx([5.0 - 0.02 * 2.0, 0, 0])
    assert late.particle_age[1] == pytest.approx(0.02)
    assert ParticleState.between(a, b, 1.0) is b


def test_rigid_and_spring_poses_between_substeps():
    q0 = np.array([[1.0, 0, 0, 0]])
    q1 = np.array([[np.cos(0.5), 0, 0, np.sin(0.5)]])  # 1 rad about z
    z = np.zeros((1, 3))
    a = RigidBodyState(z.copy(), q0, z.copy(), z.copy())
    b = RigidBodyState(np.array([[2.0, 0, 0]]), q1, np.array([[0, 4.0, 0]]), z.copy())
    mid = RigidBodyState.between(a, b, 0.25)
    assert mid.body_x[0] == pytest.approx([0.5, 0, 0])
    assert mid.body_q[0] == pytest.approx([np.cos(0.125), 0, 0, np.sin(0.125)])
    assert mid.body_P[0] == pytest.approx([0, 1.0, 0])
    s0 = SpringMeshState(np.zeros((2, 3)), np.zeros((2, 3)))
    s1 = SpringMeshState(np.ones((2, 3)), np.ones((2, 3)))
    assert SpringMeshState.between(s0, s1, 0.75).x == pytest.approx(np.full((2, 3), 0.75))


def test_world_samples_poses_inside_the_frame_and_leaves_the_path_alone():
    """Samples inside a frame give the poses there (a falling particle between sub-steps is on
    the straight line between them), and the state at the frame's end is the same as without
    them, to the bit."""
    def run(samples):
        model = particle_model(EmitterSettings("E"))
        state = model.state()
        place(state, [[0.0, 0.0, 10.0]], [[1.0, 0.0, 0.0]])
        system = ParticleSystem(ParticleSolver(model, substeps=4), state)
        world = World([system])
        off = EmitterFrame(rate=0.0, active=False)
        report = world.advance(WorldFrame(0, 0.0, DT, samples=samples), {system: ParticleDrive([off])})
        return system.state, report.poses.get(system, [])

    plain, none = run(())
    sampled, poses = run((0.1, 0.5, 0.9))
    assert none == []
    assert np.array_equal(plain.particle_x, sampled.particle_x)
    assert [p.t for p in poses] == pytest.approx([0.1 * DT, 0.5 * DT, 0.9 * DT])
    # x(t) of symplectic Euler at sub-step ends, straight in between
    h = DT / 4
    ends = [np.array([h * k, 0.0, 10.0 - 9.81 * h * h * k * (k + 1) / 2]) for k in range(5)]
    for s, pose in zip((0.1, 0.5, 0.9), poses):
        k, w = int(s * 4), s * 4 - int(s * 4)
        assert pose.particle_x[0] == pytest.approx(ends[k] + w * (ends[k + 1] - ends[k]),
                                                   abs=1e-12)
