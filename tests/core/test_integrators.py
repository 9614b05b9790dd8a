"""Integrators against closed forms: tableau conditions, measured orders, error control, energy.

Tolerances come from the method's order and step size, never from timing.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core import integrators
from physanim.core.errors import SimulationError

TABLEAUX = [
    integrators.EULER_TABLEAU,
    integrators.MIDPOINT_TABLEAU,
    integrators.RK4_TABLEAU,
    integrators.DOPRI5_TABLEAU,
]


class Oscillator:
    """``n`` independent unit-mass springs ``x'' = -omega**2 x``; ``y = [x, v]``.

    Closed form: ``x(t) = x0 cos(wt) + v0/w sin(wt)``; energy ``(v**2 + w**2 x**2) / 2`` [J/kg].
    """

    def __init__(self, omega: float, x0, v0):
        self.omega = float(omega)
        self.x0 = np.atleast_1d(np.asarray(x0, dtype=np.float64))
        self.v0 = np.atleast_1d(np.asarray(v0, dtype=np.float64))
        self.dim = 2 * self.x0.size
        self.y = np.concatenate([self.x0, self.v0])
        self.calls = 0

    def get_state(self) -> np.ndarray:
        return self.y.copy()

    def set_state(self, y: np.ndarray) -> None:
        self.y = np.array(y, dtype=np.float64)

    def derivative(self, t: float, y: np.ndarray) -> np.ndarray:
        self.calls += 1
        n = self.dim // 2
        return np.concatenate([y[n:], -self.omega**2 * y[:n]])

    def exact(self, t: float) -> np.ndarray:
        w, c, s = self.omega, math.cos(self.omega * t), math.sin(self.omega * t)
        return np.concatenate([self.x0 * c + self.v0 / w * s, -self.x0 * w * s + self.v0 * c])

    def energy(self) -> float:
        n = self.dim // 2
        return 0.5 * float(np.sum(self.y[n:] ** 2 + self.omega**2 * self.y[:n] ** 2))


class Pulse:
    """``y' = exp(-((t - t0)/sigma)**2) / (sigma sqrt(pi))``: flat, a sharp pulse at ``t0``, flat.

    Closed form ``y(t) = (erf((t - t0)/sigma) + erf(t0/sigma)) / 2`` with ``y(0) = 0``.
    """

    dim = 1

    def __init__(self, t0: float = 1.0, sigma: float = 0.01):
        self.t0, self.sigma = t0, sigma
        self.y = np.zeros(1)

    def get_state(self) -> np.ndarray:
        return self.y.copy()

    def set_state(self, y: np.ndarray) -> None:
        self.y = np.array(y, dtype=np.float64)

    def derivative(self, t: float, y: np.ndarray) -> np.ndarray:
        z = (t - self.t0) / self.sigma
        return np.array([math.exp(-z * z) / (self.sigma * math.sqrt(math.pi))])

    def exact(self, t: float) -> float:
        return 0.5 * (math.erf((t - self.t0) / self.sigma) + math.erf(self.t0 / self.sigma))


def run(integrator: integrators.Integrator, system, t_end: float, n_steps: int) -> list:
    h = t_end / n_steps
    return [integrator.step(system, i * h, h) for i in range(n_steps)]


def order_conditions(A: np.ndarray, b: np.ndarray, c: np.ndarray, order: int) -> list:
    """(value, expected) of the Butcher order conditions up to ``order`` <= 5 (all 17 trees)."""
    Ac, Ac2, Ac3 = A @ c, A @ c**2, A @ c**3
    trees = [
        (1, b.sum(), 1.0),
        (2, b @ c, 1 / 2),
        (3, b @ c**2, 1 / 3), (3, b @ Ac, 1 / 6),
        (4, b @ c**3, 1 / 4), (4, b @ (c * Ac), 1 / 8), (4, b @ Ac2, 1 / 12),
        (4, b @ (A @ Ac), 1 / 24),
        (5, b @ c**4, 1 / 5), (5, b @ (c**2 * Ac), 1 / 10), (5, b @ (c * Ac2), 1 / 15),
        (5, b @ (c * (A @ Ac)), 1 / 30), (5, b @ Ac**2, 1 / 20), (5, b @ Ac3, 1 / 20),
        (5, b @ (A @ (c * Ac)), 1 / 40), (5, b @ (A @ Ac2), 1 / 60),
        (5, b @ (A @ (A @ Ac)), 1 / 120),
    ]
    return [(value, expected) for p, value, expected in trees if p <= order]


@pytest.mark.parametrize("tableau", TABLEAUX, ids=lambda tab: tab.name)
def test_tableau_invariants(tableau):
    A, B, C = tableau.A, tableau.B, tableau.C
    assert B.sum() == pytest.approx(1.0, abs=1e-14)
    np.testing.assert_allclose(C, A.sum(axis=1), atol=1e-14)
    assert np.all(np.triu(A) == 0.0)
    for value, expected in order_conditions(A, B, C, tableau.order):
        assert value == pytest.approx(expected, abs=1e-14)
    if tableau.E is not None:
        assert tableau.E.sum() == pytest.approx(0.0, abs=1e-14)
        # The embedded solution B_hat = B - E has order ``order - 1`` but not ``order``.
        b_hat = B - tableau.E
        for value, expected in order_conditions(A, b_hat, C, tableau.order - 1):
            assert value == pytest.approx(expected, abs=1e-14)
        assert any(abs(v - e) > 1e-6 for v, e in order_conditions(A, b_hat, C, tableau.order))
    with pytest.raises(ValueError):
        A[0, 0] = 1.0  # read-only


def test_dopri5_is_first_same_as_last():
    assert integrators.DOPRI5_TABLEAU.fsal
    assert not integrators.RK4_TABLEAU.fsal


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(A=[[0, 0], [1, 0]], B=[0.5, 0.5], C=[0, 1, 2], order=2), "need A"),
        (dict(A=[[0, 1], [1, 0]], B=[0.5, 0.5], C=[1, 1], order=2), "strictly lower"),
        (dict(A=[[0, 0], [1, 0]], B=[0.5, 0.6], C=[0, 1], order=2), "B must sum to 1"),
        (dict(A=[[0, 0], [1, 0]], B=[0.5, 0.5], C=[0, 0.5], order=2), "row sums"),
        (dict(A=[[0, 0], [1, 0]], B=[0.5, 0.5], C=[0, 1], order=2, E=[1, 1]), "E must sum"),
        (dict(A=[[0, 0], [1, 0]], B=[0.5, 0.5], C=[0, 1], order=0), "order"),
    ],
)
def test_tableau_rejects_inconsistent_coefficients(kwargs, message):
    with pytest.raises(ValueError, match=message):
        integrators.Tableau(name="bad", **kwargs)


def test_rk_step_returns_stages_and_reuses_f0():
    system = Oscillator(1.0, [1.0, 2.0], [0.0, -1.0])
    y = system.get_state()
    y_new, K = integrators.rk_step(system.derivative, 0.0, y, 0.1, integrators.RK4_TABLEAU)
    assert K.shape == (4, 4) and y_new.shape == (4,)
    np.testing.assert_array_equal(K[0], system.derivative(0.0, y))
    system.calls = 0
    again, _ = integrators.rk_step(
        system.derivative, 0.0, y, 0.1, integrators.RK4_TABLEAU, f0=K[0]
    )
    assert system.calls == 3
    np.testing.assert_array_equal(again, y_new)


# --- Convergence order -----------------------------------------------------------------------


def measured_order(make, n_coarse: int, halvings: int) -> float:
    """Slope of log(global error) against log(h) on x'' = -x over 2 s, halving h each time."""
    steps, errors = [], []
    for k in range(halvings + 1):
        n_steps = n_coarse * 2**k
        system = Oscillator(1.0, 1.0, 0.5)
        run(make(), system, 2.0, n_steps)
        steps.append(2.0 / n_steps)
        errors.append(np.linalg.norm(system.y - system.exact(2.0)))
    return float(np.polyfit(np.log(steps), np.log(errors), 1)[0])


@pytest.mark.parametrize(
    "name, order",
    [("EULER", 1), ("SYMPLECTIC_EULER", 1), ("MIDPOINT", 2), ("RK4", 4), ("IMPLICIT", 1)],
)
def test_measured_global_order(name, order):
    slope = measured_order(lambda: integrators.make_integrator(name), 20, 4)
    assert slope == pytest.approx(order, abs=0.2)


def test_dopri5_fixed_step_is_fifth_order():
    slope = measured_order(lambda: integrators.ExplicitRK(integrators.DOPRI5_TABLEAU), 10, 3)
    assert slope == pytest.approx(5.0, abs=0.3)


# --- Adaptive RK45 ---------------------------------------------------------------------------


def test_rk45_meets_tolerance_in_one_big_step():
    omega, reports = 2.0 * math.pi, {}
    for tolerance in (1e-4, 1e-7):
        system = Oscillator(omega, 1.0, 0.0)
        integrator = integrators.make_integrator("RK45", tolerance)
        report = integrator.step(system, 0.0, 1.0)  # one whole period in one call
        reports[tolerance] = report
        # Each local error is held near rtol * |y| (|y| <= omega here); over the ~30-100 steps of
        # one period they add up to a few times that — allow ten.
        error = np.max(np.abs(system.y - system.exact(1.0)))
        assert error <= 10.0 * tolerance * omega
        assert report.steps >= 5
        assert report.evaluations >= 6 * (report.steps + report.rejected)
    # Step count scales as tol**(-1/5): 1000x tighter -> ~4x more steps.
    assert reports[1e-7].steps > 2 * reports[1e-4].steps


def test_rk45_step_size_shrinks_for_a_pulse_and_grows_back():
    system, dt, tolerance = Pulse(t0=1.0, sigma=0.01), 1.0 / 24.0, 1e-6
    integrator = integrators.make_integrator("RK45", tolerance)
    frames = [(i * dt, integrator.step(system, i * dt, dt)) for i in range(48)]
    # The first frame starts from f = 0 with a tiny step and grows it; then the pulse is far.
    before = [report for t, report in frames if 0.0 < t and t + dt < 0.9]
    during = [report for t, report in frames if 0.95 < t + dt and t < 1.05]
    after = [report for t, report in frames if t > 1.15]
    assert all(r.steps == 1 and r.h_last == pytest.approx(dt) for r in before)
    assert min(r.h_last for r in during) < dt / 4
    assert sum(r.steps for r in during) > 2 * len(during)
    assert all(r.steps == 1 and r.h_last == pytest.approx(dt) for r in after[2:])
    assert integrator.h_guess is not None and integrator.h_guess >= dt
    assert abs(system.y[0] - system.exact(2.0)) <= 10.0 * tolerance
    integrator.reset()
    assert integrator.h_guess is None


def test_rk45_reaches_exactly_t_plus_dt():
    system = Oscillator(3.0, 0.2, 1.0)
    integrator = integrators.make_integrator("RK45", 1e-9)
    for i in range(3):
        integrator.step(system, 0.3 * i, 0.3)
    np.testing.assert_allclose(system.y, system.exact(0.9), atol=1e-7)


def test_rk45_step_size_underflow_asks_for_looser_tolerance():
    class Singular:
        """y' = 1 / (1 - t)**2 blows up at t = 1 s."""

        dim = 1
        y = np.zeros(1)

        def get_state(self):
            return self.y.copy()

        def set_state(self, y):
            self.y = y

        def derivative(self, t, y):
            return np.array([1.0 / (1.0 - t) ** 2 if t != 1.0 else np.inf])

    with pytest.raises(SimulationError, match="raise the tolerance"):
        integrators.make_integrator("RK45", 1e-4).step(Singular(), 0.0, 2.0)


def test_rk45_step_budget_asks_for_looser_tolerance():
    integrator = integrators.AdaptiveRK(rtol=1e-10, atol=1e-12, max_steps=10)
    with pytest.raises(SimulationError, match="raise the tolerance"):
        integrator.step(Oscillator(2.0 * math.pi, 1.0, 0.0), 0.0, 1.0)


def test_adaptive_needs_an_embedded_pair_and_valid_tolerances():
    with pytest.raises(ValueError, match="RK4"):
        integrators.AdaptiveRK(integrators.RK4_TABLEAU)
    with pytest.raises(ValueError, match="-1"):
        integrators.AdaptiveRK(rtol=-1.0)


# --- Energy behaviour ------------------------------------------------------------------------


def test_symplectic_euler_bounds_energy_while_explicit_euler_grows_it():
    omega, h, n_steps = 2.0 * math.pi, 1.0 / 240.0, 10_000
    symplectic, euler = Oscillator(omega, 1.0, 0.0), Oscillator(omega, 1.0, 0.0)
    e0 = symplectic.energy()
    stepper = integrators.make_integrator("SYMPLECTIC_EULER")
    deviation = 0.0
    for i in range(n_steps):
        stepper.step(symplectic, i * h, h)
        deviation = max(deviation, abs(symplectic.energy() / e0 - 1.0))
    # Symplectic Euler conserves H~ = v^2 + w^2 x^2 - h w^2 x v exactly, and |h w^2 x v| is at
    # most (w h / 2) E, so E stays within a factor (1 +- w h / 2) / (1 -+ w h / 2) of E0.
    a = omega * h / 2.0
    assert deviation <= 2.0 * a / (1.0 - a)
    # Explicit Euler multiplies the energy by exactly (1 + w^2 h^2) every step.
    run(integrators.make_integrator("EULER"), euler, n_steps * h, n_steps)
    growth = euler.energy() / e0
    assert growth == pytest.approx((1.0 + (omega * h) ** 2) ** n_steps, rel=1e-8)
    assert growth > 100.0


class PointOscillator(Oscillator):
    """The oscillator also as a :class:`~physanim.core.integrators.PointSystem`: (n, 3) points
    whose x coordinate is the spring's (y and z drift freely)."""

    def __init__(self, omega, x0, v0):
        x = np.zeros((np.size(x0), 3))
        x[:, 0], x[:, 1] = x0, 0.25
        v = np.zeros_like(x)
        v[:, 0], v[:, 2] = v0, -0.5
        super().__init__(omega, x.ravel(), v.ravel())
        self.stored = 0
        self.into = None  # (x, v) the step is to write into (None: its own arrays)
        self.given = None  # the arrays set_points was given last

    def acceleration(self, t, x, v):
        self.calls += 1
        return -self.omega**2 * x * np.array([1.0, 0.0, 0.0])

    def derivative(self, t, y):
        n = self.dim // 2
        return np.concatenate([y[n:], self.acceleration(t, y[:n].reshape(-1, 3),
                                                         y[n:].reshape(-1, 3)).ravel()])

    def points(self):
        n = self.dim // 2
        return self.y[:n].reshape(-1, 3), self.y[n:].reshape(-1, 3)

    def new_points(self):
        return self.into

    def set_points(self, x, v):
        self.stored += 1
        self.given = (x, v)
        self.y = np.concatenate([x.ravel(), v.ravel()])


class Packed:
    """Only the packed interface of a system (no ``points``)."""

    def __init__(self, system):
        self.system = system
        self.dim = system.dim

    def get_state(self):
        return self.system.get_state()

    def set_state(self, y):
        self.system.set_state(y)

    def derivative(self, t, y):
        return self.system.derivative(t, y)


def test_symplectic_euler_steps_point_systems_on_their_points_to_the_bit():
    omega, h = 3.0, 1.0 / 48.0
    points = PointOscillator(omega, [1.0, -0.3, 2.0], [0.0, 0.7, -1.5])
    packed = PointOscillator(omega, [1.0, -0.3, 2.0], [0.0, 0.7, -1.5])
    assert isinstance(points, integrators.PointSystem)
    assert not isinstance(Packed(packed), integrators.PointSystem)
    stepper = integrators.make_integrator("SYMPLECTIC_EULER")
    for i in range(200):
        report = stepper.step(points, i * h, h)
        stepper.step(Packed(packed), i * h, h)
        assert (report.steps, report.evaluations) == (1, 1)
    assert points.stored == 200  # it went through set_points, not set_state
    np.testing.assert_array_equal(points.y, packed.y)
    # and it is symplectic Euler: x advanced with the new velocity
    q = PointOscillator(omega, [1.0], [0.0])
    stepper.step(q, 0.0, h)
    assert q.y[3] == pytest.approx(-omega**2 * h)  # v_x
    assert q.y[0] == pytest.approx(1.0 - omega**2 * h * h)  # x_x = x + h v_new
    assert q.y[5] == -0.5 and q.y[2] == pytest.approx(-0.5 * h)  # free z drift
    # where the system gives arrays to write into, the step writes the same values there
    given = PointOscillator(omega, [1.0, -0.3, 2.0], [0.0, 0.7, -1.5])
    own = PointOscillator(omega, [1.0, -0.3, 2.0], [0.0, 0.7, -1.5])
    for i in range(20):
        given.into = (np.full((3, 3), np.nan), np.full((3, 3), np.nan))
        stepper.step(given, i * h, h)
        stepper.step(own, i * h, h)
        assert given.given[0] is given.into[0] and given.given[1] is given.into[1]
        np.testing.assert_array_equal(given.y, own.y)


def test_symplectic_euler_reports_non_finite_points_and_keeps_the_state():
    class Broken(PointOscillator):
        def acceleration(self, t, x, v):
            out = np.zeros_like(x)
            out[1, 2] = np.inf
            return out

    system = Broken(1.0, [1.0, 2.0], [0.0, 0.0])
    before = system.y.copy()
    with pytest.raises(SimulationError, match="the new state"):
        integrators.make_integrator("SYMPLECTIC_EULER").step(system, 0.0, 0.1)
    np.testing.assert_array_equal(system.y, before)
    start = PointOscillator(1.0, [np.nan], [0.0])
    with pytest.raises(SimulationError, match="the state before the step"):
        integrators.make_integrator("SYMPLECTIC_EULER").step(start, 0.0, 0.1)
    with pytest.raises(ValueError, match="-0.1"):
        integrators.make_integrator("SYMPLECTIC_EULER").step(start, 0.0, -0.1)


def test_implicit_euler_damps_a_stiff_spring_that_explodes_explicit_euler():
    omega, h, x0 = 1000.0, 1.0 / 24.0, 0.01  # omega^2 = 1e6 [1/s^2], one frame per step
    stiff = Oscillator(omega, x0, 0.0)
    implicit = integrators.make_integrator("IMPLICIT")
    energies = [stiff.energy()]
    for i in range(48):
        implicit.step(stiff, i * h, h)
        energies.append(stiff.energy())
        assert np.all(np.abs(stiff.y[:1]) <= x0)
    assert all(later < earlier for earlier, later in zip(energies, energies[1:]))
    # Backward Euler on an undamped oscillator divides the energy by (1 + w^2 h^2) per step.
    assert energies[1] / energies[0] == pytest.approx(1.0 / (1.0 + (omega * h) ** 2), rel=1e-6)
    with pytest.raises(SimulationError, match="state became non-finite"):
        run(integrators.make_integrator("EULER"), Oscillator(omega, x0, 0.0), 1000 * h, 1000)


class WithJacobian(Oscillator):
    def jacobian_vector(self, t, y, u):
        n = self.dim // 2
        return np.concatenate([u[n:], -self.omega**2 * u[:n]])


@pytest.mark.parametrize("second_order", [False, True])
@pytest.mark.parametrize("omega", [50.0, 1000.0])
def test_implicit_euler_matches_backward_euler_with_an_analytic_jacobian(second_order, omega):
    h, system = 1.0 / 24.0, WithJacobian(omega, 0.01, 0.3)
    step = integrators.ImplicitEuler(rtol=1e-12, second_order=second_order)
    report = step.step(system, 0.0, h)
    assert report.evaluations == 1 and system.calls == 1  # J u never falls back to f
    # Backward Euler on a linear system: (I - h J) y_new = y.
    jacobian = np.array([[0.0, 1.0], [-(omega**2), 0.0]])
    expected = np.linalg.solve(np.eye(2) - h * jacobian, [0.01, 0.3])
    np.testing.assert_allclose(system.y, expected, rtol=1e-9)


def test_implicit_velocity_system_equals_full_system_on_a_nonlinear_pendulum():
    class Pendulum(Oscillator):
        """theta'' = -(g/l) sin(theta) - c theta'."""

        def derivative(self, t, y):
            self.calls += 1
            return np.array([y[1], -9.81 * np.sin(y[0]) - 0.5 * y[1]])

    full, reduced = Pendulum(1.0, 1.2, -0.4), Pendulum(1.0, 1.2, -0.4)
    integrators.ImplicitEuler(second_order=False).step(full, 0.0, 0.05)
    report = integrators.ImplicitEuler(second_order=True).step(reduced, 0.0, 0.05)
    assert report.evaluations == reduced.calls
    # Same linear system, solved two ways; finite-difference J u is good to ~sqrt(eps).
    np.testing.assert_allclose(reduced.y, full.y, rtol=1e-6)


def test_second_order_implicit_needs_an_even_state():
    with pytest.raises(ValueError, match="even dim"):
        integrators.make_integrator("IMPLICIT").step(Pulse(), 0.0, 0.1)


# --- Failures --------------------------------------------------------------------------------


@pytest.mark.parametrize("name", integrators.INTEGRATORS)
def test_nan_derivative_raises_simulation_error(name):
    class Broken(Oscillator):
        def derivative(self, t, y):
            return np.full(self.dim, np.nan)

    system = Broken(1.0, 1.0, 0.0)
    with pytest.raises(SimulationError, match="state became non-finite"):
        integrators.make_integrator(name).step(system, 0.0, 0.1)
    np.testing.assert_array_equal(system.y, [1.0, 0.0])  # state untouched on failure


def test_non_finite_start_state_and_bad_dt_are_reported():
    system = Oscillator(1.0, np.nan, 0.0)
    with pytest.raises(SimulationError, match="non-finite"):
        integrators.make_integrator("RK4").step(system, 0.0, 0.1)
    for dt in (0.0, -0.1, math.inf):
        with pytest.raises(ValueError, match=str(dt)):
            integrators.make_integrator("RK4").step(Oscillator(1.0, 1.0, 0.0), 0.0, dt)


def test_bicgstab_solves_a_nonsymmetric_system():
    rng = np.random.default_rng(7)
    n = 40
    matrix = np.eye(n) * 4.0 + rng.standard_normal((n, n)) / math.sqrt(n)
    b = rng.standard_normal(n)
    x, iterations = integrators.bicgstab(lambda v: matrix @ v, b, rtol=1e-10)
    assert np.linalg.norm(matrix @ x - b) <= 1e-9 * np.linalg.norm(b)
    assert 0 < iterations < n
    zero, iterations = integrators.bicgstab(lambda v: matrix @ v, np.zeros(n))
    assert iterations == 0 and np.all(zero == 0.0)


def test_bicgstab_reports_breakdown_and_non_convergence():
    b = np.ones(5)
    with pytest.raises(SimulationError, match="implicit solve failed"):
        integrators.bicgstab(lambda v: np.zeros_like(v), b)
    rng = np.random.default_rng(3)
    matrix = rng.standard_normal((30, 30))
    with pytest.raises(SimulationError, match="after 2 of 2 iterations"):
        integrators.bicgstab(lambda v: matrix @ v, rng.standard_normal(30), max_iterations=2)


# --- Factory ---------------------------------------------------------------------------------


@pytest.mark.parametrize("name", integrators.INTEGRATORS)
def test_make_integrator_builds_every_listed_method(name):
    integrator = integrators.make_integrator(name, 1e-5)
    assert isinstance(integrator, integrators.Integrator)
    system = Oscillator(1.0, 1.0, 0.0)
    report = integrator.step(system, 0.0, 0.01)
    assert report.steps >= 1 and report.evaluations >= 1 and report.h_last > 0.0
    np.testing.assert_allclose(system.y, system.exact(0.01), atol=1e-3)


def test_make_integrator_names_the_bad_value():
    with pytest.raises(ValueError, match="'VERLET'"):
        integrators.make_integrator("VERLET")
    for tolerance in (0.0, -1e-3, math.nan, math.inf):
        with pytest.raises(ValueError, match=repr(tolerance).replace(".", r"\.")):
            integrators.make_integrator("RK45", tolerance)


def test_all_finite_tells_finite_states_from_nan_and_infinities():
    from physanim.core.integrators.base import all_finite

    big = np.full(8, 1e308)  # every value finite (their sum would overflow)
    assert all_finite(big, np.zeros(3), np.zeros((0, 3)))
    for bad in (np.nan, np.inf, -np.inf):
        a = np.arange(12.0).reshape(4, 3)
        a[2, 1] = bad
        assert not all_finite(np.zeros(3), a)
    both = np.array([np.inf, -np.inf, 1.0])  # sums to NaN
    assert not all_finite(both)
    assert not all_finite(np.array([1e308, 1e308, np.nan]))


@pytest.mark.parametrize("outer", [{}, {"all": "raise"}, {"under": "warn", "over": "print"}])
def test_quiet_ignores_what_errstate_ignores_and_restores(outer):
    """A step's quick error context (:func:`quiet`) sets numpy's error modes as
    np.errstate(over, invalid, divide = "ignore") does, underflow as it was, and restores
    them, from any outer modes."""
    from physanim.core.integrators.base import quiet

    with np.errstate(**outer):
        before = np.geterr()
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            expected = np.geterr()
        with quiet():
            assert np.geterr() == expected
            np.float64(1e308) * 10.0  # (would raise or warn outside)
            np.float64(0.0) / np.float64(0.0)
        assert np.geterr() == before
