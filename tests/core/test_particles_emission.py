"""Emission: birth counts, sub-frame birth times, inherited velocity, mesh sources, sub-emitters,
ids, lifetimes and determinism. Statistical tolerances are 5 standard deviations of the stated
distribution (fixed seeds make them deterministic anyway).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from physanim.core.errors import PhysanimError
from physanim.core.particles import (
    EmitterFrame, EmitterSettings, FrameInputs, ParticleModelBuilder, ParticleSolver,
)
from physanim.tests.core.helpers import particle_model as _model, translation as _translate

FPS = 24
DT = 1.0 / FPS
ZERO_G = (0.0, 0.0, 0.0)


def _inputs(frame, emitters, gravity=ZERO_G, dt=DT, forces=()):
    return FrameInputs(frame=frame, t0=frame * dt, frame_dt=dt, gravity=gravity,
                       emitters=list(emitters), forces=forces)


def _rot_z(angle):
    c, s = math.cos(angle), math.sin(angle)
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    return m


def _cube():
    """Closed unit cube |x|, |y|, |z| <= 1 with outward-wound triangles."""
    verts = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = []
    for a, b, c, d in quads:
        tris += [(a, b, c), (a, c, d)]
    tris = np.array(tris)
    # every triangle's normal must point away from the centre
    e1 = verts[tris[:, 1]] - verts[tris[:, 0]]
    e2 = verts[tris[:, 2]] - verts[tris[:, 0]]
    centre = verts[tris].mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", np.cross(e1, e2), centre) > 0)
    return verts, tris


# -- counts -------------------------------------------------------------------------------------

def test_births_per_frame_mean_and_range():
    # births = rate + U(-1, 1) r, stochastically rounded: every count lies in [rate - r, rate + r],
    # the mean is exactly rate; Var <= r^2/3 + 1/4, so the mean of N frames is within
    # 5 sqrt((r^2/3 + 1/4) / N) of rate.
    rate, r, frames = 10.0, 4.0, 3000
    model = _model(EmitterSettings("Spray", seed=3))
    state = model.state()
    solver = ParticleSolver(model)
    ef = EmitterFrame(rate=rate, rate_random=r, lifetime=DT / 2)  # short life keeps it small
    counts = np.array([solver.advance(state, _inputs(f, [ef])).per_emitter_births[0]
                       for f in range(frames)])
    assert counts.min() >= rate - r and counts.max() <= rate + r
    assert counts.min() <= rate - r + 1 and counts.max() >= rate + r - 1  # the spread is used
    assert abs(counts.mean() - rate) <= 5.0 * math.sqrt((r * r / 3 + 0.25) / frames)


def test_fractional_rate_rounds_stochastically():
    # rate 2.3, no randomness: each frame gives 2 or 3 births, 3 with probability 0.3.
    frames = 2000
    model = _model(EmitterSettings("Drip", seed=1))
    state = model.state()
    solver = ParticleSolver(model)
    ef = EmitterFrame(rate=2.3, lifetime=DT / 2)
    counts = np.array([solver.advance(state, _inputs(f, [ef])).births for f in range(frames)])
    assert set(counts.tolist()) == {2, 3}
    assert abs(counts.mean() - 2.3) <= 5.0 * math.sqrt(0.21 / frames)


# -- sub-frame birth times ----------------------------------------------------------------------

def test_fast_emitter_leaves_an_even_trail_not_puffs():
    # The emitter jumps 10 m along x per frame; births get uniform sub-frame times, so with speed
    # 0 and no gravity the trail is uniform in x. A birth at u in frame f sits at 10 (f + u) with
    # age (F + 1 - f - u) dt at the end of frame F, hence x + 10 age / dt == 10 (F + 1) exactly.
    rate, frames = 2000, 5
    model = _model(EmitterSettings("Comet", seed=11))
    state = model.state()
    solver = ParticleSolver(model, substeps=3)
    for f in range(frames):
        ef = EmitterFrame(rate=rate, speed=0.0, lifetime=100.0,
                          matrix0=_translate(10.0 * f), matrix1=_translate(10.0 * (f + 1)))
        solver.advance(state, _inputs(f, [ef]))
    x = state.particle_x
    assert len(x) == rate * frames
    np.testing.assert_allclose(x[:, 1:], 0.0, atol=1e-12)
    np.testing.assert_allclose(x[:, 0] + 10.0 * state.particle_age / DT, 10.0 * frames,
                               atol=1e-9)
    # Kolmogorov-Smirnov against uniform on [0, 50): the 1e-6 critical value is ~2.7 / sqrt(n).
    xs = np.sort(x[:, 0]) / (10.0 * frames)
    n = len(xs)
    ks = max(np.max(np.arange(1, n + 1) / n - xs), np.max(xs - np.arange(n) / n))
    assert ks <= 2.7 / math.sqrt(n)
    # and no clumping at the frame positions: each 1 m bin holds ~200 +- 5 sqrt(200)
    hist, _ = np.histogram(x[:, 0], bins=50, range=(0.0, 50.0))
    assert np.all(np.abs(hist - 200) <= 5 * math.sqrt(200))


def test_even_timing_lays_a_moving_emitters_births_out_evenly():
    # The same moving emitter with Even Timing and 10 births a frame: births at u = (k + 1/2)
    # / 10 of each frame, so the trail's particles are exactly 1 m apart (1e-9), and the
    # births' other draws are those of random timing (the same generator stream: the same
    # random life spans).
    frames = 3
    trails = []
    for even in (True, False):
        model = _model(EmitterSettings("Rope", seed=11, even=even))
        state = model.state()
        solver = ParticleSolver(model, substeps=2)
        for f in range(frames):
            solver.advance(state, _inputs(f, [EmitterFrame(
                rate=10, speed=0.0, lifetime=100.0, lifetime_random=50.0,
                matrix0=_translate(10.0 * f),
                matrix1=_translate(10.0 * (f + 1)))]))
        trails.append(state)
    x = np.sort(trails[0].particle_x[:, 0])
    np.testing.assert_allclose(np.diff(x), 1.0, atol=1e-9)
    assert x[0] == pytest.approx(0.5)
    assert not np.allclose(np.diff(np.sort(trails[1].particle_x[:, 0])), 1.0, atol=0.05)
    np.testing.assert_array_equal(trails[0].particle_life, trails[1].particle_life)
    assert np.ptp(trails[0].particle_life) > 1.0


def test_robot_arm_throw_inherits_tangential_velocity():
    # The arm turns at w about z (90 degrees per frame) and throws from a vertex at radius R with
    # speed 0, inherit 1: each particle leaves at w R along the circle's tangent at its birth
    # point (rotations are slerped, so the vertex follows the arc). The emitter velocity is a
    # central difference with ds = 1e-4 of the frame: its magnitude is exact to (w dt ds)^2, its
    # direction (one-sided within ds of the frame's ends) to w dt ds ~ 1.6e-4 rad.
    radius = 2.0
    step = math.pi / 2
    omega = step / DT
    model = _model(EmitterSettings("Arm", source="VERTS", vertex_count=1, seed=5))
    state = model.state()
    solver = ParticleSolver(model)
    tip = np.array([[radius, 0.0, 0.0]])
    for f in range(3):
        ef = EmitterFrame(rate=50, speed=0.0, lifetime=100.0, inherit_velocity=1.0, verts0=tip,
                          matrix0=_rot_z(step * f), matrix1=_rot_z(step * (f + 1)))
        solver.advance(state, _inputs(f, [ef]))
    v = state.particle_v
    birth = state.particle_x - v * state.particle_age[:, None]  # straight flight since birth
    np.testing.assert_allclose(np.linalg.norm(birth[:, :2], axis=1), radius, rtol=1e-9)
    np.testing.assert_allclose(birth[:, 2], 0.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), omega * radius, rtol=1e-6)
    tangent = np.cross([0.0, 0.0, 1.0], birth / radius)
    cos = np.einsum("ij,ij->i", v / (omega * radius), tangent)
    assert np.all(cos >= math.cos(2 * omega * DT * 1e-4))


def test_origin_on_orbit_inherits_chord_velocity():
    # An ORIGIN emitter whose world translation orbits at radius R (child of a turning parent):
    # from two samples per frame its origin moves along the chord, so it throws at
    # |chord| / dt = w R sinc(theta / 2), i.e. w R within theta^2 / 24 relative, along the
    # chord: within theta / 2 of the tangent at the birth point. theta = 6 degrees per frame.
    radius = 2.0
    step = math.radians(6.0)
    omega = step / DT
    arm = _translate(radius)
    model = _model(EmitterSettings("Arm", seed=5))
    state = model.state()
    solver = ParticleSolver(model)
    for f in range(3):
        ef = EmitterFrame(rate=50, speed=0.0, lifetime=100.0, inherit_velocity=1.0,
                          matrix0=_rot_z(step * f) @ arm, matrix1=_rot_z(step * (f + 1)) @ arm)
        solver.advance(state, _inputs(f, [ef]))
    v = state.particle_v
    birth = state.particle_x - v * state.particle_age[:, None]
    r = np.linalg.norm(birth[:, :2], axis=1)
    assert np.all((r >= radius * math.cos(step / 2) - 1e-12) & (r <= radius + 1e-12))
    speed = np.linalg.norm(v, axis=1)
    np.testing.assert_allclose(speed, omega * radius * math.sin(step / 2) / (step / 2),
                               rtol=1e-6)
    assert np.all(np.abs(speed / (omega * radius) - 1.0) <= step * step / 24 + 1e-6)
    tangent = np.cross([0.0, 0.0, 1.0], birth / r[:, None])
    cos = np.einsum("ij,ij->i", v / speed[:, None], tangent)
    assert np.all(cos >= math.cos(step / 2) - 1e-9)


# -- mesh sources -------------------------------------------------------------------------------

def test_faces_are_area_weighted_and_uniform():
    # Triangle A (area 1) and B (area 3): P(A) = 1/4, so of n births A gets n/4 +- 5 sqrt(n 3/16).
    # Uniform barycentric sampling puts the mean of A's births at its centroid, within 5 sigma
    # (sigma of a coordinate in a triangle <= its extent / sqrt(12 nA)).
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0], [10, 0, 0], [13, 0, 0], [10, 2, 0]], float)
    tris = np.array([[0, 1, 2], [3, 4, 5]])
    model = _model(EmitterSettings("Sheet", source="FACES", triangles=tris, vertex_count=6,
                                   seed=2))
    state = model.state()
    n = 8000
    ef = EmitterFrame(rate=n, speed=1.0, lifetime=100.0, verts0=verts)
    ParticleSolver(model).advance(state, _inputs(0, [ef]))
    x, v = state.particle_x, state.particle_v
    assert len(x) == n
    # NORMAL direction: both triangles face +z; particles flew at 1 m/s since birth
    np.testing.assert_allclose(v, np.broadcast_to([0.0, 0.0, 1.0], v.shape), atol=1e-12)
    np.testing.assert_allclose(x[:, 2], state.particle_age, atol=1e-12)
    on_a = x[:, 0] < 5.0
    count_a = int(on_a.sum())
    assert abs(count_a - n / 4) <= 5 * math.sqrt(n * 3 / 16)
    a = x[on_a, :2]
    assert np.all(a >= -1e-12) and np.all(a[:, 0] + a[:, 1] / 2 <= 1 + 1e-12)  # inside A
    sigma = 2.0 / math.sqrt(12 * count_a)
    np.testing.assert_allclose(a.mean(axis=0), [1 / 3, 2 / 3], atol=5 * sigma)


def test_volume_births_are_inside_a_transformed_cube():
    verts, tris = _cube()
    m = _translate(1.0, -2.0, 0.5) @ _rot_z(0.7) @ np.diag([2.0, 0.5, 1.0, 1.0])
    model = _model(EmitterSettings("Box", source="VOLUME", triangles=tris, vertex_count=8,
                                   seed=9))
    state = model.state()
    n = 3000
    ef = EmitterFrame(rate=n, speed=0.0, lifetime=100.0, verts0=verts, matrix0=m, matrix1=m)
    ParticleSolver(model).advance(state, _inputs(0, [ef]))
    inv = np.linalg.inv(m)
    local = state.particle_x @ inv[:3, :3].T + inv[:3, 3]
    assert len(local) == n
    assert np.all(np.abs(local) <= 1.0)
    # uniform in the cube: each coordinate has mean 0, sigma 1/sqrt(3 n)
    np.testing.assert_allclose(local.mean(axis=0), 0.0, atol=5 / math.sqrt(3 * n))
    assert np.abs(local).max() > 0.95  # fills the volume, not just the centre


def test_volume_of_open_mesh_raises_naming_emitter():
    verts, tris = _cube()
    builder = ParticleModelBuilder()
    builder.add_emitter(EmitterSettings("Open Box", source="VOLUME", triangles=tris[:-1],
                                        vertex_count=8))
    with pytest.raises(PhysanimError) as info:
        builder.finalize(frame=1)
    message = str(info.value)
    assert "not closed" in message
    assert '"Open Box"' in message and "frame 1" in message


def test_faces_without_faces_raises_naming_emitter():
    builder = ParticleModelBuilder()
    builder.add_emitter(EmitterSettings("Point Cloud", source="FACES", vertex_count=3))
    with pytest.raises(PhysanimError) as info:
        builder.finalize(frame=12)
    message = str(info.value)
    assert '"Point Cloud"' in message and "no faces" in message and "frame 12" in message


# -- sub-emitters ---------------------------------------------------------------------------------

def test_deaths_sub_emitter_bursts_at_parent_death_positions():
    # Fireworks: parents fly at constant velocity and die after 0.2 s; each death gives exactly
    # `rate` children at the death point with v = inherit * v_parent + speed * cone(v_parent).
    per_death, inherit, speed, spread = 6, 0.5, 2.0, 0.3
    parent = EmitterSettings("Rocket", direction="RANDOM", seed=1)
    child = EmitterSettings("Sparks", source="DEATHS", parent=0, direction="NORMAL", seed=2)
    model = _model(parent, child)
    state = model.state()
    solver = ParticleSolver(model)
    rocket = EmitterFrame(rate=20, speed=5.0, lifetime=0.2)
    sparks = EmitterFrame(rate=per_death, speed=speed, inherit_velocity=inherit, spread=spread,
                          lifetime=100.0)
    total_deaths = 0
    for f in range(12):
        before = {int(i): (x.copy(), v.copy()) for i, x, v, e in zip(
            state.particle_id, state.particle_x, state.particle_v, state.particle_emitter)
            if e == 0}
        ef = rocket if f < 3 else EmitterFrame(active=False)
        report = solver.advance(state, _inputs(f, [ef, sparks]))
        alive = set(state.particle_id[state.particle_emitter == 0].tolist())
        dead = [i for i in before if i not in alive]
        total_deaths += len(dead)
        new = (state.particle_emitter == 1) & (state.particle_age == 0.0)
        assert report.per_emitter_births[1] == per_death * len(dead) == int(new.sum())
        if not dead:
            continue
        # no forces: a parent alive at the frame's start died at x + v dt, moving at v
        death_x = np.array([before[i][0] + before[i][1] * DT for i in dead])
        death_v = np.array([before[i][1] for i in dead])
        cx, cv = state.particle_x[new], state.particle_v[new]
        match = np.linalg.norm(cx[:, None, :] - death_x[None], axis=2).argmin(axis=1)
        np.testing.assert_allclose(cx, death_x[match], atol=1e-12)
        assert np.all(np.bincount(match, minlength=len(dead)) == per_death)
        own = cv - inherit * death_v[match]
        np.testing.assert_allclose(np.linalg.norm(own, axis=1), speed, rtol=1e-12)
        pdir = death_v[match] / np.linalg.norm(death_v[match], axis=1, keepdims=True)
        assert np.all(np.einsum("ij,ij->i", own / speed, pdir) >= math.cos(spread) - 1e-12)
    assert total_deaths >= 40  # most of the 60 rockets died inside the run


# -- ids and lifetimes ----------------------------------------------------------------------------

def test_ids_unique_and_never_reused():
    model = _model(EmitterSettings("A", direction="RANDOM", seed=1),
                   EmitterSettings("B", direction="RANDOM", seed=2))
    state = model.state()
    solver = ParticleSolver(model)
    a = EmitterFrame(rate=7, rate_random=3, lifetime=0.3, lifetime_random=0.2)
    b = EmitterFrame(rate=4, rate_random=4, lifetime=0.5, lifetime_random=0.4)
    seen: dict[int, tuple[int, float]] = {}  # id -> (emitter, age when last seen)
    gone: set[int] = set()
    previous = set()
    total_births = 0
    for f in range(100):
        total_births += solver.advance(state, _inputs(f, [a, b])).births
        ids = state.particle_id
        assert np.all(np.diff(ids) > 0)  # sorted and unique
        current = set(ids.tolist())
        assert not (current & gone), "a dead particle's id came back"
        gone |= previous - current
        for i, e, age in zip(ids.tolist(), state.particle_emitter.tolist(),
                             state.particle_age.tolist()):
            if i in seen:
                assert seen[i][0] == e and age == pytest.approx(seen[i][1] + DT)
            seen[i] = (e, age)
        previous = current
    assert state.next_id == total_births == len(seen)
    assert sorted(seen) == list(range(total_births))


def test_particles_die_when_age_reaches_life():
    # rate R per frame (exact integer), life L = 12 frames: a birth at sub-frame u is alive at
    # the end of frame f + 11 (age 12 - u frames) and dead at f + 12, so exactly 12 R are alive.
    rate, life_frames = 10, 12
    model = _model(EmitterSettings("Steady", seed=4))
    state = model.state()
    solver = ParticleSolver(model, substeps=2)
    ef = EmitterFrame(rate=rate, lifetime=life_frames * DT)
    history = []
    for f in range(40):
        report = solver.advance(state, _inputs(f, [ef]))
        history.append(report)
        assert np.all(state.particle_age < state.particle_life)
        if f >= life_frames - 1:
            assert report.alive == state.particle_count == rate * life_frames
        if f >= life_frames:
            assert report.deaths == rate
    assert history[0].alive == rate


@pytest.mark.parametrize("child_first", [False, True])
def test_births_shorter_than_a_substep_never_enter_the_state(child_first):
    # Life L = 0.2 frames, one sub-step per frame: a birth at sub-frame u would be tau = (1 - u)
    # frames old at the sub-step's end, so with tau >= L (u <= 0.8) it dies inside its birth
    # sub-step. It must not be cached older than its life span; it dies where its flight reaches
    # age L: x = (0, 0, s L - g L^2 / 2), v = (0, 0, s - g L), and its sub-emitter (speed 0,
    # inherit 1) bursts there in the same sub-step, so the children are exactly at that point —
    # also when the sub-emitter comes before its parent in the emitter list.
    life, speed, g, rate = 0.2 * DT, 3.0, 9.81, 400
    p, c = (1, 0) if child_first else (0, 1)
    flash_settings = EmitterSettings("Flash", direction="AXIS", seed=1)
    spark_settings = EmitterSettings("Spark", source="DEATHS", parent=p, seed=2)
    model = _model(*((spark_settings, flash_settings) if child_first else
                     (flash_settings, spark_settings)))
    state = model.state()
    flash = EmitterFrame(rate=rate, speed=speed, lifetime=life)
    spark = EmitterFrame(rate=1, speed=0.0, inherit_velocity=1.0, lifetime=100.0)
    frames = [spark, flash] if child_first else [flash, spark]
    report = ParticleSolver(model).advance(state, _inputs(0, frames, (0.0, 0.0, -g)))
    parents = state.particle_emitter == p
    assert np.all(state.particle_age[parents] < state.particle_life[parents])
    assert report.per_emitter_births[p] == rate
    assert report.born_dead == rate - int(parents.sum()) == report.deaths
    assert abs(report.born_dead - 0.8 * rate) <= 5 * math.sqrt(rate * 0.8 * 0.2)
    children = state.particle_emitter == c
    assert int(children.sum()) == report.born_dead == report.per_emitter_births[c]
    np.testing.assert_array_equal(state.particle_age[children], 0.0)
    np.testing.assert_allclose(state.particle_x[children],
                               np.broadcast_to([0, 0, speed * life - 0.5 * g * life * life],
                                               (report.born_dead, 3)), atol=1e-12)
    np.testing.assert_allclose(state.particle_v[children],
                               np.broadcast_to([0, 0, speed - g * life], (report.born_dead, 3)),
                               atol=1e-12)


def test_short_lived_particles_over_many_substeps():
    # Same emitter, 3 sub-steps of h = 1/3 frame, no gravity (every flight is exact): after
    # every frame no particle is as old as its life span; each child flies at the parent's
    # speed along z, so z / s - child age is the parent's age at death: exactly L for births
    # that died at once, in [L, L + h) for those that died one sub-step later. Every parent
    # death gave exactly one child (nothing is lost or late).
    life, speed, h = 0.2 * DT, 3.0, DT / 3
    model = _model(EmitterSettings("Flash", direction="AXIS", seed=1),
                   EmitterSettings("Spark", source="DEATHS", parent=0, seed=2))
    state = model.state()
    solver = ParticleSolver(model, substeps=3)
    flash = EmitterFrame(rate=50, speed=speed, lifetime=life)
    spark = EmitterFrame(rate=1, speed=0.0, inherit_velocity=1.0, lifetime=100.0)
    deaths = born_dead = 0
    for f in range(10):
        report = solver.advance(state, _inputs(f, [flash, spark]))
        deaths += report.deaths
        born_dead += report.born_dead
        assert np.all(state.particle_age < state.particle_life)
    children = state.particle_emitter == 1
    assert int(children.sum()) == deaths
    death_age = state.particle_x[children, 2] / speed - state.particle_age[children]
    assert np.all((death_age >= life - 1e-12) & (death_age < life + h))
    assert np.count_nonzero(np.abs(death_age - life) <= 1e-12) >= born_dead > 0


def test_random_larger_than_value_is_rejected_for_life_and_size():
    model = _model(EmitterSettings("Spray"))
    solver = ParticleSolver(model)
    cases = [
        (EmitterFrame(lifetime=0.3, lifetime_random=0.5),
         ("lifetime_random 0.5 s is larger than lifetime 0.3 s: life spans would become "
          "negative — lower lifetime_random")),
        (EmitterFrame(size=0.05, size_random=0.08),
         ("size_random 0.08 is larger than size 0.05: sizes would become negative — lower "
          "size_random")),
    ]
    for ef, expected in cases:
        with pytest.raises(PhysanimError) as info:
            solver.advance(model.state(), _inputs(7, [ef]))
        err = info.value
        assert (err.obj, err.frame, err.kind) == ("Spray", 7, "emitter")
        assert str(err).startswith('emitter "Spray" at frame 7: ' + expected)
    # equal is fine: the extremes reach zero, never below
    state = model.state()
    solver.advance(state, _inputs(0, [EmitterFrame(rate=500, lifetime=1.0, lifetime_random=1.0,
                                                  size=0.05, size_random=0.05)]))
    assert np.all(state.particle_life >= 0.0) and np.all(state.particle_size >= 0.0)


def test_speed_random_larger_than_speed_flips_direction():
    # speed 1 +- 3: a third of the draws are negative and fly against the axis (by design).
    n = 3000
    model = _model(EmitterSettings("Both Ways", direction="AXIS", seed=5))
    state = model.state()
    ParticleSolver(model).advance(state, _inputs(0, [EmitterFrame(rate=n, speed=1.0,
                                                                  speed_random=3.0)]))
    vz = state.particle_v[:, 2]
    np.testing.assert_array_equal(state.particle_v[:, :2], 0.0)
    assert vz.min() < -1.9 and vz.max() > 3.9
    assert abs(np.count_nonzero(vz < 0) - n / 3) <= 5 * math.sqrt(n * 2 / 9)


def test_steady_state_with_random_rate_and_life():
    # Mean alive count = mean rate * mean life in frames (Little's law): 10 * 12 = 120; with
    # independent frames the fluctuation is ~ sqrt(120), averaged over 100 frames well inside 5%.
    model = _model(EmitterSettings("Noisy", seed=8))
    state = model.state()
    solver = ParticleSolver(model)
    ef = EmitterFrame(rate=10, rate_random=5, lifetime=12 * DT, lifetime_random=6 * DT)
    alive = [solver.advance(state, _inputs(f, [ef])).alive for f in range(140)]
    assert np.mean(alive[40:]) == pytest.approx(120, rel=0.05)


# -- determinism ----------------------------------------------------------------------------------

def _run(settings_list, frames=50, seed=0):
    model = _model(*settings_list, seed=seed)
    state = model.state()
    solver = ParticleSolver(model, substeps=2)
    ef = EmitterFrame(rate=12, rate_random=6, speed=3.0, speed_random=1.0, lifetime=1.0,
                      lifetime_random=0.5, size_random=0.02, spread=0.5,
                      matrix0=_translate(0.0), matrix1=_translate(0.1))
    for f in range(frames):
        solver.advance(state, _inputs(f, [ef] * len(settings_list), gravity=(0, 0, -9.81)))
    return state


def _arrays(state, emitter=None):
    sel = slice(None) if emitter is None else state.particle_emitter == emitter
    return {name: getattr(state, name)[sel] for name in
            ("particle_x", "particle_v", "particle_age", "particle_life", "particle_size")}


def test_same_seed_is_bit_identical():
    settings = [EmitterSettings("Fountain", direction="RANDOM", seed=21)]
    a, b = _run(settings), _run(settings)
    assert a.particle_count > 100
    np.testing.assert_array_equal(a.particle_id, b.particle_id)
    for name, value in _arrays(a).items():
        np.testing.assert_array_equal(value, _arrays(b)[name], err_msg=name)


def test_different_seed_differs():
    a = _run([EmitterSettings("Fountain", direction="RANDOM", seed=21)])
    b = _run([EmitterSettings("Fountain", direction="RANDOM", seed=22)])
    c = _run([EmitterSettings("Fountain", direction="RANDOM", seed=21)], seed=1)
    for other in (b, c):
        n = min(a.particle_count, other.particle_count)
        assert not np.array_equal(a.particle_x[:n], other.particle_x[:n])


def test_second_emitter_does_not_change_the_first():
    # The new emitter is inserted *before* the existing one, so the Fountain's index shifts from
    # 0 to 1: its generator must depend on its name and seeds, not on its position.
    first = EmitterSettings("Fountain", direction="RANDOM", seed=21)
    alone = _run([first])
    both = _run([EmitterSettings("Other", direction="RANDOM", seed=99), first])
    renamed = _run([EmitterSettings("Renamed", direction="RANDOM", seed=99), first])
    assert np.count_nonzero(both.particle_emitter == 0) > 100
    ref = _arrays(alone)
    for state in (both, renamed):
        for name, value in _arrays(state, emitter=1).items():
            np.testing.assert_array_equal(value, ref[name], err_msg=name)


def test_renaming_an_emitter_reseeds_it():
    # The name is part of the seed: same seeds, different name, different particles.
    a = _run([EmitterSettings("Fountain", direction="RANDOM", seed=21)])
    b = _run([EmitterSettings("Fountain.001", direction="RANDOM", seed=21)])
    n = min(a.particle_count, b.particle_count)
    assert not np.array_equal(a.particle_x[:n], b.particle_x[:n])


# -- a frame's values checked ---------------------------------------------------------------------

_BAD_FRAME_VALUES = [
    ("rate", -1.0, "rate must be >= 0"), ("rate", math.nan, "rate must be finite"),
    ("rate_random", math.inf, "rate_random must be finite"),
    ("speed", -0.5, "speed must be >= 0"), ("speed_random", math.nan, "speed_random"),
    ("lifetime", -2.0, "lifetime must be >= 0"), ("lifetime_random", 3.0, "life spans"),
    ("size", -0.1, "size must be >= 0"), ("size_random", 0.06, "sizes would become negative"),
    ("spread", -0.1, "spread must be >= 0"), ("inherit_velocity", math.inf, "inherit_velocity"),
    ("mass", 0.0, "mass must be > 0"), ("mass", math.nan, "mass must be > 0"),
    ("rate", 2e7, "at most 10000000"), ("launch", (0.0, math.nan, 0.0), "launch velocity"),
    ("launch", (1.0, 2.0), "launch velocity"), ("launch", (10**400, -10**400, 0), "launch"),
    ("inherit_velocity", 10**400, "inherit_velocity must be finite"),
    ("mass", 10**400, "mass must be > 0"),
    ("matrix0", np.diag([1.0, 1.0, math.inf, 1.0]), "matrix0 has non-finite"),
    ("matrix1", np.eye(3), "matrix1 must be a 4x4"),
    ("matrices", np.stack([np.eye(4), np.full((4, 4), math.nan)]), "sub-frame matrix 1"),
    ("verts0", np.array([[0.0, 0.0, 0.0], [math.nan, 0.0, 0.0]]), "vertex 1"),
    ("verts1", np.array([[0.0, -math.inf, 0.0]]), "vertex 0"),
]


@pytest.mark.parametrize("key, value, words", _BAD_FRAME_VALUES,
                         ids=[f"{k}={v!r}"[:40] for k, v, _ in _BAD_FRAME_VALUES])
def test_every_bad_frame_value_is_refused_naming_it(key, value, words):
    """The one-expression check of a frame's values (the common case, every frame) lets no
    bad value through: each is refused with the full check's message."""
    good = EmitterFrame(rate=5.0, rate_random=1.0, lifetime=2.0, lifetime_random=1.0,
                        size=0.05, size_random=0.01, matrices=np.stack([np.eye(4)] * 3),
                        verts0=np.zeros((2, 3)), verts1=np.ones((2, 3)))
    assert good.validated("Spout") is good
    bad = dataclasses.replace(good, **{key: value})
    with pytest.raises(ValueError) as info:
        bad.validated("Spout")
    assert 'emitter "Spout"' in str(info.value) and words in str(info.value)


def test_frame_values_whose_sum_overflows_are_still_valid():
    """Finite values whose sum overflows fail the quick check only: the full one passes them."""
    huge = np.full((4, 4), 1e308)
    frame = EmitterFrame(matrix0=huge, matrix1=huge, verts0=np.full((3, 3), 1e308))
    assert frame.validated("Far") is frame
