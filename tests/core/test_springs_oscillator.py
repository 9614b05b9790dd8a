"""Two masses and one spring against the closed form of the damped harmonic oscillator.

Two equal masses m joined by one spring (no gravity, no shear, no bending, no drag) move only in
the relative coordinate q = |x1 - x0| - r, with reduced mass mu = m1 m2 / (m1 + m2):

    mu q'' = -k q - kd q',   omega = sqrt(k / mu),   gamma = kd / (2 mu),

so the period is T = 2 pi sqrt(mu / k) and the amplitude decays as exp(-gamma t). The motion stays
on the spring's axis, where the spring force is exactly linear in q: every integrator's step is a
linear map S of (q, q') and its period and decay have closed forms too (derived per test).

Every frame is one step (frame_dt = h, one substep) so every step is sampled.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core.errors import PhysanimError, SimulationError
from physanim.core.springs import (SpringFrameInputs, SpringMeshBuilder, SpringMeshSettings,
                                   SpringMeshSolver)
from physanim.core.springs.implicit import BaraffWitkin

MASS = 2.0  # total [kg]: 1 kg per vertex (EVEN)
MU = 0.25 * MASS  # reduced mass of two equal masses m/2 each: (m/2)^2 / m [kg]
PERIOD = 1.0  # [s]
OMEGA = 2.0 * math.pi / PERIOD
K = MU * OMEGA ** 2  # [N/m]
H = 1.0 / 200.0  # step [s]: omega h = 0.0314
Z = OMEGA * H
STRETCH = 0.1  # initial q [m] (rest length 1 m)

# The implicit solve is inexact by design: CG stops once the residual is below TOLERANCE *
# max(|b|, h |M| * 1 m/s^2), after at least one iteration from its warm start (the previous
# steps' dv, extrapolated). Here the preconditioner is exact (two vertices: a direct solve), so
# every step is exact to rounding; the allowance below is what an accepted inexact solve could
# err by — tolerance * z relative per turning point of q (two per period), 2x for the scale:
CG_EPS = 2.0 * BaraffWitkin.TOLERANCE * Z


def _pair(integrator: str, damping: float = 0.0):
    settings = SpringMeshSettings("Pair", mass=MASS, stiffness=K, damping=damping,
                                  shear_stiffness=0.0, bend_mode="NONE", drag=0.0)
    model = SpringMeshBuilder(settings, [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], [[0, 1]],
                              np.zeros((0, 3))).finalize(1)
    return model, SpringMeshSolver(model, integrator, 1, frame_dt=H, frame=1)


def _run(integrator: str, steps: int, damping: float = 0.0):
    """(t, q, qdot) sampled after every step, starting at rest with q = STRETCH."""
    model, solver = _pair(integrator, damping)
    state = model.state()
    state.x[1, 0] += STRETCH
    q, qd = [STRETCH], [0.0]
    for k in range(steps):
        solver.advance(state, SpringFrameInputs(k + 1, k * H, H, gravity=(0.0, 0.0, 0.0)))
        # the motion must stay on the axis (the closed form assumes it)
        assert np.all(state.x[:, 1:] == 0.0) and np.all(state.v[:, 1:] == 0.0)
        q.append(state.x[1, 0] - state.x[0, 0] - 1.0)
        qd.append(state.v[1, 0] - state.v[0, 0])
    return H * np.arange(steps + 1), np.array(q), np.array(qd)


def _measured_period(t: np.ndarray, q: np.ndarray) -> float:
    """Twice the mean spacing of zero crossings (linearly interpolated). Near a crossing q'' =
    -omega^2 q vanishes, so interpolation errs by O(h (omega h)^2) ~ 1e-8 s per crossing."""
    s = np.nonzero((q[:-1] > 0.0) != (q[1:] > 0.0))[0]
    tc = t[s] + H * q[s] / (q[s] - q[s + 1])
    assert len(tc) >= 5
    return 2.0 * (tc[-1] - tc[0]) / (len(tc) - 1)


# discrete frequency of each method on q'' = -omega^2 q (step map eigenvalue exp(i omega_h h)):
#   symplectic Euler: cos(omega_h h) = 1 - z^2/2  -> omega_h = 2 asin(z/2)/h, T_h/T - 1 ~ -z^2/24
#   RK4: omega_h h = arg R(iz), R(w) = 1 + w + w^2/2 + w^3/6 + w^4/24,     T_h/T - 1 ~ z^4/120
#   backward Euler: eigenvalue 1/(1 - iz) -> omega_h h = atan z,           T_h/T - 1 ~ +z^2/3
# (backward Euler's *phase* error is second order; its first-order error is the amplitude
# damping, tested below.) Each continuous bound is 1.5x the leading term plus 1e-6 for the
# zero-crossing measurement.
def _rk4_r(w: complex) -> complex:
    return 1 + w + w ** 2 / 2 + w ** 3 / 6 + w ** 4 / 24


DISCRETE_OMEGA_H = {
    "SYMPLECTIC_EULER": 2.0 * math.asin(Z / 2.0),
    "RK4": float(np.angle(_rk4_r(1j * Z))),
    "IMPLICIT": math.atan(Z),
}
PERIOD_BOUND = {"SYMPLECTIC_EULER": 1.5 * Z ** 2 / 24, "RK4": 1.5 * Z ** 4 / 120,
                "IMPLICIT": 1.5 * Z ** 2 / 3}


@pytest.mark.parametrize("integrator", ["SYMPLECTIC_EULER", "RK4", "IMPLICIT"])
def test_two_mass_period_is_2pi_sqrt_mu_over_k(integrator):
    t, q, _ = _run(integrator, 640)  # 3.2 periods: 6 zero crossings
    measured = _measured_period(t, q)
    discrete = 2.0 * math.pi * H / DISCRETE_OMEGA_H[integrator]
    # a phase error of CG_EPS [rad] per turning point, 6 of them in 5 half periods: CG_EPS
    solve = CG_EPS if integrator == "IMPLICIT" else 0.0
    assert measured == pytest.approx(discrete, rel=1e-6 + solve)  # the method's closed form
    assert abs(measured / PERIOD - 1.0) <= PERIOD_BOUND[integrator] + 1e-6 + solve


def test_implicit_euler_numerical_damping_is_first_order():
    """Undamped backward Euler: S = (I - hA)^-1 shrinks q^2 + (q'/omega)^2 by exactly 1/(1 + z^2)
    per step ((q, q'/omega) turns by atan z and scales by 1/sqrt(1 + z^2)): an O(h) amplitude
    decay rate omega^2 h / 2 with no physical damping at all (after 2 s: 0.67 of the energy).
    Tolerance: 2 CG_EPS per turning point, 4 turning points."""
    t, q, qd = _run("IMPLICIT", 400)
    energy = q ** 2 + (qd / OMEGA) ** 2
    expected = energy[0] * (1.0 + Z ** 2) ** -np.arange(len(t))
    np.testing.assert_allclose(energy, expected, rtol=8.0 * CG_EPS)
    assert energy[-1] / energy[0] < 0.7


GAMMA = 0.5  # [1/s]
KD = 2.0 * MU * GAMMA  # [N s/m]


def test_rk4_damped_amplitude_follows_exp_minus_kd_over_2mu_t():
    """The exact envelope of q = e^{-gamma t}(a cos w_d t + b sin w_d t) is
    q^2 + ((q' + gamma q)/w_d)^2 = (a^2 + b^2) e^{-2 gamma t}. RK4's local error is
    |z|^5/120 ~ 3e-10 per step, 600 steps: 2e-7 relative; bound 1e-6."""
    t, q, qd = _run("RK4", 600, damping=KD)
    omega_d = math.sqrt(OMEGA ** 2 - GAMMA ** 2)
    envelope = q ** 2 + ((qd + GAMMA * q) / omega_d) ** 2
    np.testing.assert_allclose(envelope / envelope[0], np.exp(-2.0 * GAMMA * t), rtol=1e-6)


# Amplitude decay of a linear 2x2 step map S: |eigenvalue|^2 = det S, and det S is measured
# exactly from consecutive states since [y_{n+1}, y_{n+2}] = S [y_n, y_{n+1}] (Liouville: the
# continuous flow contracts areas by e^{-2 gamma t}). Closed forms of det S per step:
#   symplectic Euler: 1 - 2 gamma h              -> rate gamma + gamma^2 h + O(h^2)
#   RK4: |R(h lambda)|^2, lambda = -gamma + i w_d -> rate gamma + O(h^4)
#   backward Euler: 1 / (1 + 2 gamma h + z^2)     -> rate gamma + omega^2 h/2 - gamma^2 h + O(h^2)
LAMBDA = complex(-GAMMA, math.sqrt(OMEGA ** 2 - GAMMA ** 2))
DET_S = {
    "SYMPLECTIC_EULER": 1.0 - 2.0 * GAMMA * H,
    "RK4": abs(_rk4_r(H * LAMBDA)) ** 2,
    "IMPLICIT": 1.0 / (1.0 + 2.0 * GAMMA * H + Z ** 2),
}
RATE_BOUND = {  # |rate - gamma|: 1.5x the leading term
    "SYMPLECTIC_EULER": 1.5 * GAMMA ** 2 * H,
    "RK4": 1.5 * abs(LAMBDA) ** 5 * H ** 4 / 120,
    "IMPLICIT": 1.5 * (OMEGA ** 2 * H / 2 + GAMMA ** 2 * H),
}


@pytest.mark.parametrize("integrator", ["SYMPLECTIC_EULER", "RK4", "IMPLICIT"])
def test_damped_decay_rate(integrator):
    steps = 400
    _, q, qd = _run(integrator, steps, damping=KD)
    area = q[:-1] * qd[1:] - q[1:] * qd[:-1]  # det [y_n, y_{n+1}]
    duration = (steps - 1) * H
    rate = -math.log(area[-1] / area[0]) / (2.0 * duration)
    # implicit: each of the 4 turning points changes the area by up to 2 CG_EPS
    solve = 8.0 * CG_EPS / (2.0 * duration) if integrator == "IMPLICIT" else 0.0
    assert rate == pytest.approx(-math.log(DET_S[integrator]) / (2.0 * H), rel=1e-7, abs=solve)
    assert abs(rate - GAMMA) <= RATE_BOUND[integrator] + solve


def test_explicit_euler_blow_up_is_reported_with_object_and_frame():
    """Explicit Euler grows an undamped spring by sqrt(1 + (omega h)^2) per step at any h; the
    up-front check allows omega h < 0.1, hoping damping wins. Without damping it does not: at
    omega h = 0.099 a 0.5 m stretch reaches the tear limit (50 rest lengths) after
    ln(98) / 0.0049 ~ 940 steps. The error must name the object and the frame it happened at."""
    omega = 0.099 * 24.0  # one step per frame at 24 fps
    settings = SpringMeshSettings("Wobbly", mass=1.0, stiffness=0.25 * omega ** 2, damping=0.0,
                                  shear_stiffness=0.0, bend_mode="NONE", drag=0.0)
    model = SpringMeshBuilder(settings, [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], [[0, 1]],
                              np.zeros((0, 3))).finalize(1)
    solver = SpringMeshSolver(model, "EULER", 1, frame_dt=1 / 24, frame=1)  # passes the check
    state = model.state()
    state.x[1, 0] += 0.5
    with pytest.raises(SimulationError) as info:
        for frame in range(1, 3000):
            solver.advance(state, SpringFrameInputs(frame, frame / 24, 1 / 24,
                                                    gravity=(0.0, 0.0, 0.0)))
    message = str(info.value)
    assert info.value.obj == "Wobbly" and '"Wobbly"' in message
    assert 800 < info.value.frame < 1200 and f"frame {info.value.frame}" in message
    assert "IMPLICIT" in message and "substeps" in message


def test_implicit_blow_up_does_not_advise_the_implicit_integrator():
    """A failed implicit solve (here a non-finite velocity: CG loses positive definiteness)
    names the object and the frame, and advises what an implicit mesh can change: not the
    integrator it already uses."""
    settings = SpringMeshSettings("Sheet", mass=1.0, stiffness=100.0, damping=0.0,
                                  shear_stiffness=0.0, bend_mode="NONE", drag=0.0)
    model = SpringMeshBuilder(settings, [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], [[0, 1]],
                              np.zeros((0, 3))).finalize(1)
    solver = SpringMeshSolver(model, "IMPLICIT", 1, frame_dt=1 / 24, frame=1)
    state = model.state()
    state.v[1, 0] = np.nan
    with pytest.raises(SimulationError) as info:
        solver.advance(state, SpringFrameInputs(3, 3 / 24, 1 / 24, gravity=(0.0, 0.0, 0.0)))
    message = str(info.value)
    assert info.value.obj == "Sheet" and "frame 3" in message and "blew up" in message
    assert "substeps" in message and "IMPLICIT" not in message


def test_stiff_spring_rejected_up_front_for_explicit_methods():
    """The same spring 1000x stiffer fails at construction, not mid-bake."""
    omega = 0.099 * 24.0
    settings = SpringMeshSettings("Stiff", mass=1.0, stiffness=250.0 * omega ** 2, damping=0.0,
                                  shear_stiffness=0.0, bend_mode="NONE", drag=0.0)
    model = SpringMeshBuilder(settings, [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], [[0, 1]],
                              np.zeros((0, 3))).finalize(1)
    for integrator in ("EULER", "MIDPOINT", "SYMPLECTIC_EULER", "RK4"):
        with pytest.raises(PhysanimError, match=f'"Stiff".*{integrator}.*IMPLICIT'):
            SpringMeshSolver(model, integrator, 1, frame_dt=10.0, frame=1)
    SpringMeshSolver(model, "IMPLICIT", 1, frame_dt=10.0, frame=1)  # never refused
