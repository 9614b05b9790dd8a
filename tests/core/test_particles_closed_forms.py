"""Particle solver against closed forms: projectile, bounce height (on a half space and on a
mesh), friction on a slope, drag, springs. Each tolerance is derived (in a comment) from the
integrator's order and the step size.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core.contact import SKIN, ColliderFrame
from physanim.core.forces import DampedSprings, Drag, ParticleView
from physanim.core.particles import (
    EmitterFrame, EmitterSettings, FrameInputs, ParticleSolver, SpringLink,
)
from physanim.tests.core.helpers import (
    mesh_collider, particle_model as _model, sheet, translation as _translate,
)

G = 9.81
FPS = 24
DT = 1.0 / FPS


# -- helpers ------------------------------------------------------------------------------------

def _place(state, x, v, emitter=0, mass=1.0, life=1e9):
    """Put particles straight into a State (exact initial conditions, no emission randomness)."""
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    v = np.atleast_2d(np.asarray(v, dtype=np.float64))
    n = len(x)
    return state.append(emitter, x, v, np.broadcast_to(np.asarray(mass, float), (n,)).copy(),
                        np.zeros(n), np.full(n, life), np.full(n, 0.05))


def _inputs(frame, dt=DT, gravity=(0.0, 0.0, -G), colliders=(), forces=(), emitters=None,
            emitter_count=1):
    if emitters is None:
        emitters = [EmitterFrame(active=False)] * emitter_count
    return FrameInputs(frame=frame, t0=frame * dt, frame_dt=dt, gravity=gravity,
                       emitters=emitters, colliders=colliders, forces=forces)


def _rot_x(theta):
    c, s = math.cos(theta), math.sin(theta)
    m = np.eye(4)
    m[1:3, 1:3] = [[c, -s], [s, c]]
    return m


# -- projectile -----------------------------------------------------------------------------------

X0 = np.array([0.5, -1.0, 2.0])
V0 = np.array([3.0, 1.0, 8.0])
GV = np.array([0.0, 0.0, -G])


@pytest.mark.parametrize("integrator", ["RK4", "MIDPOINT", "RK45"])
def test_projectile_exact_for_second_order_methods(integrator):
    # x(t) = x0 + v0 t + g t^2 / 2 is a quadratic: every RK method of order >= 2 integrates it
    # exactly, so only rounding remains: ~ steps * eps * |x| ~ 48 * 2e-16 * 20 m -> 1e-11 bound.
    model = _model(EmitterSettings("Ball"))
    state = model.state()
    _place(state, X0, V0)
    solver = ParticleSolver(model, integrator, substeps=2)
    for f in range(48):
        solver.advance(state, _inputs(f))
        t = (f + 1) * DT
        np.testing.assert_allclose(state.particle_x[0], X0 + V0 * t + 0.5 * GV * t * t, atol=1e-11)
        np.testing.assert_allclose(state.particle_v[0], V0 + GV * t, atol=1e-11)
    assert state.t == pytest.approx(2.0)


@pytest.mark.parametrize("substeps", [1, 2, 5])
def test_projectile_symplectic_euler_first_order_known_error(substeps):
    # v_{n+1} = v_n + h g, x_{n+1} = x_n + h v_{n+1}  =>  v exact and
    # x_n = x0 + v0 t + g h^2 n (n + 1) / 2 = exact(t) + g h t / 2: an O(h) error of known form.
    model = _model(EmitterSettings("Ball"))
    state = model.state()
    _place(state, X0, V0)
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps=substeps)
    h = DT / substeps
    frames = 24
    for f in range(frames):
        solver.advance(state, _inputs(f))
    n = frames * substeps
    t = n * h
    exact = X0 + V0 * t + 0.5 * GV * t * t
    np.testing.assert_allclose(state.particle_x[0], exact + 0.5 * GV * h * t, atol=1e-11)
    np.testing.assert_allclose(state.particle_v[0], V0 + GV * t, atol=1e-11)
    # and the error really is there (first order, not accidentally exact)
    assert abs(state.particle_x[0, 2] - exact[2]) == pytest.approx(0.5 * G * h * t, rel=1e-9)


# -- restitution ----------------------------------------------------------------------------------

def _ground(kind, k):
    """A frictionless ground in z = 0 of restitution k, the analytic half space or a flat mesh,
    and the (x, y) to drop onto it at (on the mesh, beside its vertices: one is at the origin)."""
    if kind == "MESH":
        verts, tris = sheet(5, 20.0)
        return mesh_collider("Ground", verts, tris, restitution=k, friction=0.0), (0.3, -0.2)
    ground = ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4), restitution=k,
                           friction=0.0)
    return ground, (0.0, 0.0)


@pytest.mark.parametrize("kind", ["HALF_SPACE", "MESH"])
@pytest.mark.parametrize("k", [0.3, 0.7, 1.0])
def test_bounce_apex_is_restitution_squared_times_height(k, kind):
    # RK4 is exact in free flight, so after the bounce z + vz^2 / (2 g) is the apex exactly.
    # The response moves the rest of the hit sub-step along the reflected velocity without
    # gravity: that adds k v_i tau (tau <= h) to the apex, plus SKIN; the chord-vs-parabola
    # time-of-impact error is below g h^2. So 0 - g h^2 <= apex - k^2 H <= k v_i h + SKIN + g h^2,
    # on either kind of ground.
    H = 2.0
    substeps = 8
    h = DT / substeps
    v_i = math.sqrt(2.0 * G * H)
    model = _model(EmitterSettings("Ball"))
    state = model.state()
    ground, xy = _ground(kind, k)
    _place(state, [*xy, H], [0.0, 0.0, 0.0])
    solver = ParticleSolver(model, "RK4", substeps=substeps)
    apex = None
    for f in range(40):
        report = solver.advance(state, _inputs(f, colliders=[ground]))
        assert state.particle_x[0, 2] >= 0.0
        if state.particle_v[0, 2] > 0.0:
            assert report.collisions == 1
            z, vz = state.particle_x[0, 2], state.particle_v[0, 2]
            apex = z + vz * vz / (2.0 * G)
            break
    assert apex is not None, "the particle never bounced"
    slack = G * h * h
    assert -slack <= apex - k * k * H <= k * v_i * h + SKIN + slack


def test_resting_on_ground_after_bounces_does_not_jitter():
    # Dropped with k = 0.5, bounces die out (a bounce slower than 2 g h becomes contact); then
    # the particle must rest: never below the surface, height constant within SKIN, vz == 0.
    model = _model(EmitterSettings("Ball"))
    state = model.state()
    _place(state, [0.0, 0.0, 0.5], [0.0, 0.0, 0.0])
    ground = ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4), restitution=0.5,
                           friction=0.5)
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps=2)
    for f in range(60):
        solver.advance(state, _inputs(f, colliders=[ground]))
        assert state.particle_x[0, 2] >= 0.0
    heights = []
    for f in range(60, 160):
        solver.advance(state, _inputs(f, colliders=[ground]))
        heights.append(state.particle_x[0, 2])
        assert abs(state.particle_v[0, 2]) < 1e-9
    heights = np.array(heights)
    assert heights.min() >= 0.0
    assert heights.max() - heights.min() <= SKIN
    assert heights.max() <= 2 * SKIN


# -- friction on a tilted plane -------------------------------------------------------------------

THETA = math.radians(30.0)


def _slope():
    m = _rot_x(THETA)
    normal = m[:3, 2]  # local +z is the outward normal of the half space z <= 0
    downhill = np.array([0.0, -math.cos(THETA), -math.sin(THETA)])
    assert abs(normal @ downhill) < 1e-15
    return m, normal, downhill


@pytest.mark.parametrize("integrator", ["SYMPLECTIC_EULER", "RK4"])
def test_sliding_on_slope_accelerates_at_coulomb_rate(integrator):
    # mu < tan(theta): kinetic friction, a = g (sin - mu cos) along the slope. Once sliding, the
    # force is constant, so both methods reproduce dv/dt exactly (rounding only): rel 1e-9.
    mu = 0.2
    m, normal, downhill = _slope()
    model = _model(EmitterSettings("Puck"))
    state = model.state()
    _place(state, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    slope = ColliderFrame("Slope", "HALF_SPACE", m, m, restitution=0.0, friction=mu)
    solver = ParticleSolver(model, integrator, substeps=2)
    speeds = {}
    for f in range(60):
        solver.advance(state, _inputs(f, colliders=[slope]))
        x, v = state.particle_x[0], state.particle_v[0]
        # on the surface (a rounding-level dip is pushed out by SKIN), not sinking
        assert -1e-12 <= x @ normal <= SKIN + 1e-12
        assert abs(v @ normal) < 1e-9
        speeds[f] = v @ downhill
    expected = G * (math.sin(THETA) - mu * math.cos(THETA))
    measured = (speeds[50] - speeds[20]) / (30 * DT)
    assert measured == pytest.approx(expected, rel=1e-9)


def test_static_friction_holds_on_slope_when_mu_exceeds_tan():
    # mu > tan(theta): static friction must hold the particle. At most one sub-step may pass
    # before friction engages, so the slip is bounded by g sin(theta) h^2 and the final speed
    # by rounding. Over 100 frames: no sinking, no jitter (vn ~ 0, height within SKIN).
    mu = 0.8
    assert mu > math.tan(THETA)
    m, normal, downhill = _slope()
    model = _model(EmitterSettings("Puck"))
    state = model.state()
    _place(state, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    slope = ColliderFrame("Slope", "HALF_SPACE", m, m, restitution=0.0, friction=mu)
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps=1)
    heights = []
    for f in range(100):
        solver.advance(state, _inputs(f, colliders=[slope]))
        x, v = state.particle_x[0], state.particle_v[0]
        heights.append(x @ normal)
        assert x @ normal >= -1e-12
        assert abs(v @ normal) < 1e-9
    assert max(heights) - min(heights) <= SKIN + 1e-12
    slip = np.linalg.norm(state.particle_x[0])
    assert slip <= G * math.sin(THETA) * DT * DT, f"particle crept {slip:.3f} m down the slope"
    assert np.linalg.norm(state.particle_v[0]) < 1e-6


# -- drag ---------------------------------------------------------------------------------------

def test_linear_drag_follows_exponential_approach_rk4():
    # m v' = m g - k v  =>  v(t) = vT (1 - exp(-k t / m)), vT = m g / k. RK4's amplification
    # R(-z) differs from exp(-z) by <= z^5 / 120 (z = k h / m), and |R| <= 1, so after n steps
    # |v_n - v(t_n)| <= n vT z^5 / 120.
    mass, k = 2.0, 4.0
    lam = k / mass
    v_t = mass * G / k
    model = _model(EmitterSettings("Drop"))
    state = model.state()
    _place(state, [0.0, 0.0, 100.0], [0.0, 0.0, 0.0], mass=mass)
    solver = ParticleSolver(model, "RK4")
    z = lam * DT
    for f in range(96):
        solver.advance(state, _inputs(f, forces=[Drag("Air", linear=k)]))
        t = (f + 1) * DT
        bound = (f + 1) * v_t * z ** 5 / 120.0 + 1e-12
        assert abs(state.particle_v[0, 2] + v_t * (1.0 - math.exp(-lam * t))) <= bound
    assert state.particle_v[0, 2] == pytest.approx(-v_t, rel=1e-3)


def test_linear_drag_terminal_velocity_symplectic_euler():
    # Explicit update of v: v_{n+1} - (-vT) = (1 - k h / m)(v_n + vT): the fixed point is exactly
    # the terminal velocity m g / k and the gap shrinks by (1 - k h / m) per step.
    mass, k = 0.5, 3.0
    v_t = mass * G / k
    model = _model(EmitterSettings("Drop"))
    state = model.state()
    _place(state, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], mass=mass)
    solver = ParticleSolver(model, "SYMPLECTIC_EULER")
    frames = 240
    for f in range(frames):
        solver.advance(state, _inputs(f, forces=[Drag("Air", linear=k)]))
    gap = v_t * (1.0 - k * DT / mass) ** frames
    assert abs(state.particle_v[0, 2] + v_t) <= gap + 1e-12
    np.testing.assert_allclose(state.particle_v[0, :2], 0.0)


def test_quadratic_drag_terminal_velocity():
    # m g = k2 v^2 at terminal speed: vT = sqrt(m g / k2); RK4 with h = 1/96 s converges to the
    # fixed point to rounding after ~20 time constants (tau = vT / g ~ 0.3 s).
    mass, k2 = 1.5, 0.4
    v_t = math.sqrt(mass * G / k2)
    model = _model(EmitterSettings("Drop"))
    state = model.state()
    _place(state, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], mass=mass)
    solver = ParticleSolver(model, "RK4", substeps=4)
    for f in range(200):
        solver.advance(state, _inputs(f, forces=[Drag("Air", linear=0.0, quadratic=k2)]))
    assert state.particle_v[0, 2] == pytest.approx(-v_t, rel=1e-9)


# -- springs ------------------------------------------------------------------------------------

def _zero_crossings(t, y):
    """Times where y changes sign, by linear interpolation between samples."""
    idx = np.nonzero(np.sign(y[:-1]) != np.sign(y[1:]))[0]
    return t[idx] - y[idx] * (t[idx + 1] - t[idx]) / (y[idx + 1] - y[idx])


def test_spring_link_period_uses_reduced_mass():
    # Two particles (1 kg then 3 kg) born by an emitter moving along x, joined by a SpringLink of
    # rest length L, no gravity: the separation oscillates as L + A cos(w t), w = sqrt(k / mu),
    # mu = m1 m2 / (m1 + m2). Sampled at h = 1/240 s with RK4 (phase error ~ n (w h)^5 / 120 ~
    # 1e-7), the period from linearly interpolated zero crossings is off by at most
    # h (w h)^2 / 6 ~ 6e-7 s per crossing: assert to 1e-5 relative.
    fps = 240
    dt = 1.0 / fps
    k, rest = 40.0, 0.6
    m1, m2 = 1.0, 3.0
    mu = m1 * m2 / (m1 + m2)
    period = 2.0 * math.pi * math.sqrt(mu / k)
    model = _model(EmitterSettings("Chain", link=SpringLink(stiffness=k, damping=0.0,
                                                             rest_length=rest)))
    state = model.state()
    solver = ParticleSolver(model, "RK4")
    frames = [
        EmitterFrame(rate=1, speed=0.0, mass=m1, lifetime=100.0, matrix0=_translate(0.0),
                     matrix1=_translate(0.2)),
        EmitterFrame(rate=1, speed=0.0, mass=m2, lifetime=100.0, matrix0=_translate(0.2),
                     matrix1=_translate(0.4)),
    ]
    times, sep = [], []
    total = int(3.2 * period * fps)
    for f in range(total):
        ef = frames[f] if f < 2 else EmitterFrame(active=False)
        report = solver.advance(state, _inputs(f, dt=dt, gravity=(0, 0, 0), emitters=[ef]))
        if f < 2:
            assert report.births == 1
            continue
        if f == 2:
            assert state.link_a.tolist() == [0] and state.link_b.tolist() == [1]
            assert state.link_rest.tolist() == [rest]
        x, v = state.particle_x, state.particle_v
        # internal forces only: momentum stays zero, the motion stays on the x axis
        np.testing.assert_allclose(m1 * v[0] + m2 * v[1], 0.0, atol=1e-12)
        np.testing.assert_allclose(x[:, 1:], 0.0, atol=1e-12)
        times.append((f + 1) * dt)
        sep.append(x[1, 0] - x[0, 0])
    crossings = _zero_crossings(np.array(times), np.array(sep) - rest)
    assert len(crossings) >= 5
    half_periods = np.diff(crossings)
    np.testing.assert_allclose(half_periods, period / 2.0, rtol=1e-5)


def test_damped_spring_matches_underdamped_closed_form():
    # mu r'' = -k (r - L) - c r', r'(0) = 0: r - L = A e^{-g t}(cos wd t + g/wd sin wd t) with
    # g = c / (2 mu), wd = sqrt(k/mu - g^2). RK4 global error <= n (w h)^5 / 120 * A ~ 2e-7 A.
    m1, m2 = 2.0, 0.5
    mu = m1 * m2 / (m1 + m2)
    k, c, rest = 30.0, 0.8, 1.0
    gam = c / (2.0 * mu)
    wd = math.sqrt(k / mu - gam * gam)
    r0 = 1.3
    amp = r0 - rest
    model = _model(EmitterSettings("Pair"))
    state = model.state()
    _place(state, [[0.0, 0.0, 0.0], [r0, 0.0, 0.0]], np.zeros((2, 3)), mass=[m1, m2])
    spring = DampedSprings(np.array([1]), np.array([0]), stiffness=k, damping=c,
                           rest=np.array([rest]))
    fps = 240
    dt = 1.0 / fps
    solver = ParticleSolver(model, "RK4")
    for f in range(480):
        solver.advance(state, _inputs(f, dt=dt, gravity=(0, 0, 0), forces=[spring]))
        t = (f + 1) * dt
        r = state.particle_x[1, 0] - state.particle_x[0, 0]
        expected = rest + amp * math.exp(-gam * t) * (math.cos(wd * t)
                                                      + gam / wd * math.sin(wd * t))
        assert abs(r - expected) <= 1e-6 * amp
        np.testing.assert_allclose(m1 * state.particle_v[0] + m2 * state.particle_v[1], 0.0,
                                   atol=1e-12)


def test_damped_springs_conserve_momentum_and_angular_momentum():
    # Each spring adds f to i and -f to j along x_i - x_j: the net force and net torque vanish.
    rng = np.random.default_rng(7)
    n = 6
    x = rng.normal(size=(n, 3))
    v = rng.normal(size=(n, 3))
    i = np.array([0, 1, 2, 3, 4, 0, 5])
    j = np.array([1, 2, 3, 4, 5, 3, 1])
    springs = DampedSprings(i, j, stiffness=12.0, damping=0.7, rest=rng.uniform(0.5, 2.0, len(i)))
    f = np.zeros((n, 3))
    springs.apply(ParticleView(x, v, np.ones(n), 0.0), f)
    assert np.abs(f).max() > 1.0  # the springs do push
    np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.cross(x, f).sum(axis=0), 0.0, atol=1e-12)


def test_damped_spring_force_formula():
    # f_i = -[ks (|l| - r) + kd (l' . l)/|l|] l/|l| (Witkin & Baraff), checked by hand.
    x = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0]])
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    springs = DampedSprings(np.array([1]), np.array([0]), stiffness=2.0, damping=0.5,
                            rest=np.array([4.0]))
    f = np.zeros((2, 3))
    springs.apply(ParticleView(x, v, np.ones(2), 0.0), f)
    u = np.array([0.6, 0.8, 0.0])
    mag = 2.0 * (5.0 - 4.0) + 0.5 * (1.0 * 0.6)
    np.testing.assert_allclose(f[1], -mag * u)
    np.testing.assert_allclose(f[0], mag * u)
