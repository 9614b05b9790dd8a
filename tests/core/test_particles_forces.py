"""Force objects against their laws (wind, gust noise, attractor, vortex) and the error raised
when a force drives the state non-finite.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from physanim.core.bounds import StateBounds
from physanim.core.errors import SimulationError
from physanim.core.forces import Attractor, Drag, Vortex, Wind
from physanim.core.particles import EmitterFrame, EmitterSettings, FrameInputs, ParticleSolver
from physanim.core.forces import ParticleView
from physanim.tests.core.helpers import particle_model as _model, place as _place

FPS = 24
DT = 1.0 / FPS
ZERO_G = (0.0, 0.0, 0.0)


def _inputs(frame, forces=(), emitter_count=1, dt=DT, gravity=ZERO_G):
    return FrameInputs(frame=frame, t0=frame * dt, frame_dt=dt, gravity=gravity,
                       emitters=[EmitterFrame(active=False)] * emitter_count, forces=forces)


def _force(force, x, v=None, mass=None, t=0.0):
    x = np.asarray(x, dtype=np.float64)
    v = np.zeros_like(x) if v is None else v
    mass = np.ones(len(x)) if mass is None else mass
    f = np.zeros_like(x)
    force.apply(ParticleView(x, v, mass, t), f)
    return f


# -- wind ---------------------------------------------------------------------------------------

def test_wind_pushes_with_strength_over_mass():
    # f = strength * d (a force, not an acceleration): a = strength / m along d. Constant force,
    # so RK4 gives x = a t^2 / 2 exactly (rounding only).
    wind = Wind("Breeze", direction=(3.0, 0.0, 4.0), strength=2.0)
    d = np.array([0.6, 0.0, 0.8])
    masses = np.array([0.5, 4.0])
    f = _force(wind, np.zeros((2, 3)), mass=masses)
    np.testing.assert_allclose(f, np.vstack([2.0 * d, 2.0 * d]))
    model = _model(EmitterSettings("Leaf"))
    state = model.state()
    _place(state, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], mass=0.5)
    _place(state, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], mass=4.0)
    solver = ParticleSolver(model, "RK4")
    for f in range(24):
        solver.advance(state, _inputs(f, [wind]))
    t = 1.0
    a = 2.0 / masses[:, None] * d
    np.testing.assert_allclose(state.particle_x, 0.5 * a * t * t, atol=1e-12)
    np.testing.assert_allclose(state.particle_v, a * t, atol=1e-12)


def test_wind_noise_is_deterministic_per_seed():
    x = np.random.default_rng(0).uniform(-5, 5, size=(50, 3))
    a = Wind("Gust", (1, 0, 0), 1.0, noise=1.0, seed=4)
    b = Wind("Gust", (1, 0, 0), 1.0, noise=1.0, seed=4)
    c = Wind("Gust", (1, 0, 0), 1.0, noise=1.0, seed=5)
    np.testing.assert_array_equal(a.field(x, 0.3), b.field(x, 0.3))
    assert np.abs(a.field(x, 0.3) - c.field(x, 0.3)).max() > 0.1


def test_wind_noise_zero_mean_unit_variance():
    # Sum of 6 plane waves of amplitude sqrt(2/6): each component has mean 0 and variance 1 over
    # space. 20000 points over 200 wavelengths are nearly independent samples: the mean is
    # within 5/sqrt(n) ~ 0.035 and the variance within 0.15 of 1.
    wind = Wind("Gust", (1, 0, 0), 1.0, noise=1.0, noise_scale=0.5, seed=1)
    x = np.random.default_rng(2).uniform(-50, 50, size=(20000, 3))
    n = wind.field(x, 0.0)
    assert np.all(np.abs(n.mean(axis=0)) <= 5 / math.sqrt(len(x)))
    np.testing.assert_allclose(n.var(axis=0), 1.0, atol=0.15)


def test_wind_noise_is_smooth():
    # Each component is sum_w a sin(k_w . x + phase + omega t) with |k_w| = 2 pi / scale,
    # a = sqrt(2/6): it is Lipschitz with constant 6 a 2 pi / scale in x, and
    # 6 a 2 pi speed 1.5 in t (omega <= 1.5 * 2 pi speed).
    scale, speed = 2.0, 0.7
    wind = Wind("Gust", (0, 1, 0), 1.0, noise=1.0, noise_scale=scale, noise_speed=speed, seed=9)
    amp = math.sqrt(2.0 / 6.0)
    rng = np.random.default_rng(3)
    x = rng.uniform(-10, 10, size=(2000, 3))
    step = rng.normal(size=(2000, 3))
    step *= 1e-3 / np.linalg.norm(step, axis=1, keepdims=True)
    dn = np.abs(wind.field(x + step, 1.0) - wind.field(x, 1.0)).max()
    assert dn <= 6 * amp * 2 * math.pi / scale * 1e-3
    dt_n = np.abs(wind.field(x, 1.0 + 1e-3) - wind.field(x, 1.0)).max()
    assert dt_n <= 6 * amp * 2 * math.pi * speed * 1.5 * 1e-3
    far = np.abs(wind.field(x + 0.37 * scale, 1.0) - wind.field(x, 1.0)).max()
    assert far > 0.5  # it does vary on the scale of noise_scale


def test_wind_with_noise_applies_strength_times_direction_plus_field():
    wind = Wind("Gust", (0, 0, 2), 3.0, noise=0.4, seed=2)
    x = np.random.default_rng(5).normal(size=(10, 3))
    f = _force(wind, x, t=0.25)
    np.testing.assert_allclose(f, 3.0 * (np.array([0, 0, 1.0]) + 0.4 * wind.field(x, 0.25)))


# -- attractor ------------------------------------------------------------------------------------

@pytest.mark.parametrize("falloff", [0.0, 1.0, 2.0, 3.5])
def test_attractor_follows_falloff_law(falloff):
    # f = strength * u / d^falloff towards the centre for min_distance <= d <= max_distance,
    # 0 beyond max_distance; mass does not enter (it is a force).
    centre = np.array([1.0, -2.0, 0.5])
    att = Attractor("Sun", tuple(centre), strength=3.0, falloff=falloff, min_distance=0.2,
                    max_distance=5.0)
    rng = np.random.default_rng(6)
    u = rng.normal(size=(7, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    d = np.array([0.2, 0.5, 1.0, 2.0, 4.9, 5.1, 30.0])
    x = centre + u * d[:, None]
    f = _force(att, x, mass=rng.uniform(0.1, 3, 7))
    expected = 3.0 / d[:, None] ** falloff * -u
    expected[d > 5.0] = 0.0
    np.testing.assert_allclose(f, expected, rtol=1e-12, atol=1e-15)


def test_attractor_inside_min_distance_is_bounded_and_continuous():
    # Inside min_distance the pull stays towards the centre, never exceeds its value at
    # min_distance (no singularity) and joins it continuously; it vanishes at the centre.
    centre = np.array([0.0, 0.0, 1.0])
    att = Attractor("Sun", tuple(centre), strength=2.0, falloff=2.0, min_distance=0.5)
    u = np.array([0.0, 0.6, 0.8])
    d = np.array([0.0, 1e-6, 0.1, 0.3, 0.5 - 1e-9, 0.5])
    f = _force(att, centre + u * d[:, None])
    cap = 2.0 / 0.5 ** 2
    mag = np.linalg.norm(f, axis=1)
    assert np.all(mag <= cap * (1 + 1e-12))
    np.testing.assert_allclose(f[1:] / mag[1:, None], np.broadcast_to(-u, (5, 3)), atol=1e-12)
    assert mag[-2] == pytest.approx(cap, rel=1e-6)
    np.testing.assert_array_equal(f[0], 0.0)


def test_negative_strength_repels():
    att = Attractor("Fan", (0.0, 0.0, 0.0), strength=-2.0, falloff=1.0)
    f = _force(att, [[2.0, 0.0, 0.0]])
    np.testing.assert_allclose(f, [[1.0, 0.0, 0.0]])


def test_attractor_circular_orbit():
    # Inverse square pull S / r^2 on mass m: v = sqrt(S / (m r)) keeps a circle of radius r at
    # w = v / r. RK4 error per step ~ r (w h)^5, after n steps <= n r (w h)^5.
    strength, mass, radius = 2.0, 0.5, 1.0
    v = math.sqrt(strength / (mass * radius))
    w = v / radius
    att = Attractor("Sun", (0.0, 0.0, 0.0), strength=strength, falloff=2.0, min_distance=1e-3)
    model = _model(EmitterSettings("Planet"))
    state = model.state()
    _place(state, [radius, 0.0, 0.0], [0.0, v, 0.0], mass=mass)
    substeps = 4
    h = DT / substeps
    solver = ParticleSolver(model, "RK4", substeps=substeps)
    frames = int(2 * math.pi / w / DT) + 1  # a full orbit
    for f in range(frames):
        solver.advance(state, _inputs(f, [att]))
        t = (f + 1) * DT
        n = (f + 1) * substeps
        expected = radius * np.array([math.cos(w * t), math.sin(w * t), 0.0])
        assert np.linalg.norm(state.particle_x[0] - expected) <= n * radius * (w * h) ** 5


# -- vortex -------------------------------------------------------------------------------------

def test_vortex_swirls_perpendicular_to_axis_and_radius():
    # f = strength * (a x r_perp) / |r_perp|: magnitude `strength`, perpendicular to the axis and
    # to the radial direction, turning counter-clockwise about a; zero on the axis itself.
    centre = np.array([0.5, 0.5, 0.0])
    axis = np.array([1.0, 1.0, 1.0]) / math.sqrt(3.0)
    vortex = Vortex("Twister", tuple(centre), (2.0, 2.0, 2.0), strength=1.5)
    x = centre + np.random.default_rng(8).normal(size=(50, 3))
    f = _force(vortex, x)
    r = x - centre
    r_perp = r - (r @ axis)[:, None] * axis
    np.testing.assert_allclose(np.linalg.norm(f, axis=1), 1.5)
    np.testing.assert_allclose(f @ axis, 0.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("ij,ij->i", f, r_perp), 0.0, atol=1e-12)
    assert np.all(np.cross(r_perp, f) @ axis > 0.0)
    on_axis = _force(vortex, [centre + 2.0 * axis])
    np.testing.assert_array_equal(on_axis, 0.0)


# -- non-finite states ----------------------------------------------------------------------------

NON_FINITE_VALUE = re.compile(r"(velocity|position) became \[[^\]]*(nan|inf)", re.IGNORECASE)


def test_nan_from_attractor_names_emitter_frame_and_value():
    # A particle sitting exactly on an attractor with a vanishing min_distance: inf * 0 = NaN in
    # the force, from frame 5 on (the attractor appears then). The error must name the emitter,
    # the frame and the non-finite value.
    model = _model(EmitterSettings("Fountain"))
    state = model.state()
    _place(state, [1.0, 2.0, 3.0], [0.0, 0.0, 0.0])
    solver = ParticleSolver(model, "RK4")
    for f in range(5):
        solver.advance(state, _inputs(f))
    singular = Attractor("Singularity", (1.0, 2.0, 3.0), 1.0, min_distance=1e-300)
    with pytest.raises(SimulationError) as info:
        solver.advance(state, _inputs(5, [singular]))
    error = info.value
    message = str(error)
    assert error.obj == "Fountain" and error.frame == 5
    assert '"Fountain"' in message and "frame 5" in message
    assert NON_FINITE_VALUE.search(message), message


def test_nan_blames_the_emitter_whose_particle_failed():
    # Two emitters: "Calm" has a particle at rest on the singular attractor (it goes NaN),
    # "Fast" a fast but harmless particle elsewhere. The message must name "Calm".
    model = _model(EmitterSettings("Calm"), EmitterSettings("Fast"))
    state = model.state()
    _place(state, [1.0, 2.0, 3.0], [0.0, 0.0, 0.0], emitter=0)
    _place(state, [50.0, 0.0, 0.0], [30.0, 0.0, 0.0], emitter=1)
    solver = ParticleSolver(model, "RK4")
    singular = Attractor("Singularity", (1.0, 2.0, 3.0), 1.0, min_distance=1e-300,
                         max_distance=1.0)
    with pytest.raises(SimulationError) as info:
        solver.advance(state, _inputs(2, [singular], emitter_count=2))
    assert info.value.obj == "Calm", str(info.value)
    assert NON_FINITE_VALUE.search(str(info.value)), str(info.value)


def test_a_particle_going_nan_as_it_dies_is_a_blow_up_not_a_death(monkeypatch):
    """A value that goes non-finite after the integrator (here: the colliders' response,
    made to fail) in the sub-step its particle dies must stop the bake naming it, not leave
    with the dead (nor burst NaN sub-particles)."""
    import sys

    model = _model(EmitterSettings("Sparks"))
    state = model.state()
    _place(state, [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]],
           life=0.5 * DT)  # both die in the first sub-step
    solver_module = sys.modules[ParticleSolver.__module__]
    real = solver_module.respond

    def failing(*args, **kwargs):
        done = real(*args, **kwargs)
        done.x[1] = np.nan
        return done
    monkeypatch.setattr(solver_module, "respond", failing)
    with pytest.raises(SimulationError) as info:
        ParticleSolver(model).advance(state, _inputs(0))
    assert info.value.obj == "Sparks" and NON_FINITE_VALUE.search(str(info.value))


def test_overflow_from_huge_drag_raises_simulation_error():
    # Explicit Euler with k h / m ~ 4e298 multiplies v by -4e298 per step: the second step
    # overflows to inf. That must surface as SimulationError naming emitter, frame and value
    # (not as a numpy warning or a silent inf).
    model = _model(EmitterSettings("Sparks"))
    state = model.state()
    _place(state, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0])
    drag = Drag("Tar", linear=1e300)
    # at the default bounds the first step already stops: 4e298 m/s is beyond the speed limit
    with pytest.raises(SimulationError, match=r'"Sparks" at frame 0: particle 0 speed 4\.\d+e\+298 '
                                              r"m/s is beyond the speed limit"):
        ParticleSolver(model, "EULER").advance(state, _inputs(0, [drag]))
    state = model.state()
    _place(state, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0])
    solver = ParticleSolver(model, "EULER", bounds=StateBounds(1e308, 1e308))  # no bounds
    solver.advance(state, _inputs(0, [drag]))
    assert np.isfinite(state.particle_v).all()
    with pytest.raises(SimulationError) as info:
        solver.advance(state, _inputs(1, [drag]))
    message = str(info.value)
    assert '"Sparks"' in message and "frame 1" in message
    assert NON_FINITE_VALUE.search(message), message
