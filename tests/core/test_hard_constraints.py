"""Hard constraints on point sets (Witkin & Baraff's constrained dynamics + projection) against
closed forms: the pendulum's period, a bead on a circular wire, a chain that never stretches,
momentum of a free chain, the constraint force of a body at rest, and hard particle links."""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core.forces import (
    Feedback, Gravity, HardConstraints, OnPlanes, ParticleView, Pins, Rods, Tethers, on_circles,
)
from physanim.core.forces import constraints as hard
from physanim.core.integrators import make_integrator
from physanim.core.particles import EmitterFrame, EmitterSettings, ParticleSolver, SpringLink
from physanim.tests.core.helpers import particle_model, translation
from physanim.tests.core.test_particles_closed_forms import DT, _inputs

G = 9.81
FIRST_ORDER = ("SYMPLECTIC_EULER", "EULER", "IMPLICIT")


class PointOde:
    """Point masses under gravity and hard constraints, as an integrator sees them (the same
    derivative the particle solver builds: forces, then constraint forces last)."""

    def __init__(self, x, v, mass, constraints, gravity=(0.0, 0.0, -G)):
        self.x, self.v = np.array(x, float), np.array(v, float)
        self.mass = np.asarray(mass, float)
        self.constraints = constraints
        self.forces = [Gravity(gravity)] if any(gravity) else []
        self.n = len(self.mass)
        self.dim = 6 * self.n

    def get_state(self):
        return np.concatenate([self.x.ravel(), self.v.ravel()])

    def set_state(self, y):
        self.x = y[:3 * self.n].reshape(self.n, 3).copy()
        self.v = y[3 * self.n:].reshape(self.n, 3).copy()

    def derivative(self, t, y):
        x, v = y[:3 * self.n].reshape(self.n, 3), y[3 * self.n:].reshape(self.n, 3)
        view = ParticleView(x, v, self.mass, t)
        f = np.zeros((self.n, 3))
        for force in self.forces:
            force.apply(view, f)
        self.constraints.constrain(view, f)
        return np.concatenate([v.ravel(), (f / self.mass[:, None]).ravel()])

    def run(self, integrator, h, seconds, each=None):
        """Step, projecting after each step as the particle solver does."""
        method = make_integrator(integrator)
        t = 0.0
        for _ in range(int(round(seconds / h))):
            x0 = self.x.copy()
            method.step(self, t, h)
            t += h
            self.constraints.project(self.x, self.v, t, 1.0 / self.mass,
                                     start=x0 if integrator in FIRST_ORDER else None, h=h)
            if each is not None:
                each(t, self)


@pytest.mark.parametrize("integrator", ["SYMPLECTIC_EULER", "RK4"])
def test_pendulum_on_a_rod_keeps_its_period_and_length(integrator):
    # A point on a rigid massless rod of length L from a fixed pivot, released at 0.05 rad:
    # T = 2 pi sqrt(L/g) (1 + theta^2/16 + ...) (the amplitude term is 1.6e-4: kept). The issue
    # asks 0.5 %; at h = 1/240 s both first- and fourth-order steps land within 0.05 %. The
    # rod's length is held by the projection to its tolerance (1e-10 m): asserted < 1e-6 L over
    # 10 s.
    length, theta = 1.0, 0.05
    ode = PointOde([[length * math.sin(theta), 0.0, -length * math.cos(theta)]], [[0, 0, 0]],
                   [1.0], HardConstraints([Tethers([0], (0, 0, 0), length)]))
    crossings, drift, last = [], [0.0], [ode.x[0, 0]]

    def each(t, s):
        drift[0] = max(drift[0], abs(np.linalg.norm(s.x[0]) - length))
        x = s.x[0, 0]
        if last[0] > 0.0 >= x:
            crossings.append(t - (1 / 240) * x / (x - last[0]))
        last[0] = x

    ode.run(integrator, 1 / 240, 10.0, each)
    period = float(np.mean(np.diff(crossings)))
    closed = 2 * math.pi * math.sqrt(length / G) * (1 + theta ** 2 / 16)
    assert len(crossings) >= 4
    assert abs(period / closed - 1.0) < 5e-4
    assert drift[0] < 1e-6 * length


def _bead(integrator, h, seconds=10.0):
    """A 0.2 kg bead on a vertical circular wire (radius 0.5 m), started at the height of the
    centre going up at 1 m/s: it swings over the bottom. Returns (largest distance off the wire,
    largest energy error / (m g R))."""
    radius, m = 0.5, 0.2
    ode = PointOde([[radius, 0, 0]], [[0, 0, 1.0]], [m],
                   HardConstraints(on_circles([0], (0, 0, 0), (0, 1, 0), radius)))
    energy = lambda s: 0.5 * m * float(s.v[0] @ s.v[0]) + m * G * s.x[0, 2]  # noqa: E731
    e0, off, de = energy(ode), [0.0], [0.0]

    def each(t, s):
        off[0] = max(off[0], abs(np.linalg.norm(s.x[0]) - radius), abs(s.x[0, 1]))
        de[0] = max(de[0], abs(energy(s) - e0))

    ode.run(integrator, h, seconds, each)
    return off[0], de[0] / (m * G * radius)


def test_bead_on_a_wire_stays_on_it_and_keeps_energy_to_the_methods_order():
    # On the wire to 1e-6 m (projection tolerance 1e-10) for every method. Energy: RK4's error
    # falls ~2^4 (measured ~33) when h halves; symplectic Euler's stays bounded and first order
    # (RATTLE: halves with h; without it, the projected symplectic Euler gained 1.2 m g R at
    # h = 1/240 s and 370 m g R at 1/120 s); midpoint's falls ~2^2 or better.
    results = {(m, h): _bead(m, h) for m in ("SYMPLECTIC_EULER", "MIDPOINT", "RK4")
               for h in (1 / 120, 1 / 240)}
    for off, _ in results.values():
        assert off < 1e-6
    rk4 = results["RK4", 1 / 120][1] / results["RK4", 1 / 240][1]
    assert rk4 > 12.0 and results["RK4", 1 / 240][1] < 1e-6
    mid = results["MIDPOINT", 1 / 120][1] / results["MIDPOINT", 1 / 240][1]
    assert mid > 3.0
    se_coarse, se_fine = results["SYMPLECTIC_EULER", 1 / 120][1], \
        results["SYMPLECTIC_EULER", 1 / 240][1]
    assert se_coarse < 0.06 and 1.6 < se_coarse / se_fine < 2.4


def _chain(links, spacing=0.1):
    x = np.zeros((links + 1, 3))
    x[:, 0] = np.arange(links + 1) * spacing
    return x


@pytest.mark.parametrize("integrator, h", [("SYMPLECTIC_EULER", 1 / 48), ("RK4", 1 / 240)])
def test_twenty_link_chain_never_stretches(integrator, h):
    # A chain of 20 rods hung by its first point from a pivot, released horizontal: it whips
    # down and swings for 5 s, symplectic Euler at the product's default step (24 fps, 2
    # sub-steps). The issue asks < 0.1 % stretch; the projection holds 1e-10 m. RK4 needs the
    # smaller step: its stages leave the constraints while the free end whips at 20 m/s on
    # 10 cm links (a link turning ~5 rad per 1/48 s step), and it blows up there.
    links = 20
    x = _chain(links)[1:]  # point k at (0.1 (k + 1), 0, 0); the pivot at the origin
    rods = Rods(np.arange(0, links - 1), np.arange(1, links), np.full(links - 1, 0.1))
    ode = PointOde(x, np.zeros_like(x), np.full(links, 0.05),
                   HardConstraints([rods, Tethers([0], (0, 0, 0), 0.1)]))
    worst, lowest = [0.0], [0.0]

    def each(t, s):
        lengths = np.linalg.norm(np.diff(np.vstack([np.zeros(3), s.x]), axis=0), axis=1)
        worst[0] = max(worst[0], float(np.max(np.abs(lengths / 0.1 - 1.0))))
        lowest[0] = min(lowest[0], float(np.min(s.x[:, 2])))

    ode.run(integrator, h, 5.0, each)
    assert worst[0] < 1e-3 * 1e-3  # a millionth, a thousand times inside the 0.1 %
    assert lowest[0] < -1.5  # it did swing down (the chain is 2 m long)


@pytest.mark.parametrize("integrator", ["SYMPLECTIC_EULER", "RK4"])
def test_free_chain_conserves_linear_momentum(integrator):
    # Rods are internal: every impulse they make (forces and projections alike) is equal and
    # opposite along the rod, so the momentum of a free chain with random masses and velocities
    # stays put to rounding with gravity off, while the chain whirls (links turn up to 0.5 rad a
    # step, so symplectic Euler's RATTLE falls back to the current gradients: still momentum-
    # exact).
    rng = np.random.default_rng(1)
    n = 21
    x = _chain(n - 1)
    x[:, 1] = rng.normal(0.0, 0.02, n)
    v = rng.normal(0.0, 1.0, (n, 3))
    m = rng.uniform(0.5, 2.0, n)
    lengths = np.linalg.norm(x[1:] - x[:-1], axis=1)
    constraints = HardConstraints([Rods(np.arange(1, n), np.arange(n - 1), lengths)])
    constraints.project(x, v, 0.0, 1.0 / m)
    ode = PointOde(x, v, m, constraints, gravity=(0.0, 0.0, 0.0))
    p0 = (m[:, None] * ode.v).sum(axis=0)
    ode.run(integrator, 1 / 48, 2.0)
    p1 = (m[:, None] * ode.v).sum(axis=0)
    assert np.max(np.abs(p1 - p0)) < 1e-9 * np.max(np.abs(p0))
    stretch = np.linalg.norm(ode.x[1:] - ode.x[:-1], axis=1) / lengths - 1.0
    assert np.max(np.abs(stretch)) < 1e-6


def test_constraint_force_holds_a_point_at_rest():
    # A 2 kg point hanging at rest on a tether, and one resting on a tilted plane (normal n):
    # Witkin's force is exactly the reaction — gravity cancelled for the hanging one, and for
    # the plane only gravity's normal part (m g . n) n, the tangential part left to slide.
    hc = HardConstraints([Tethers([0], (0, 0, 1.0), 1.0)])
    f = np.array([[0.0, 0.0, -2.0 * G]])
    lam = hc.force(np.zeros((1, 3)), np.zeros((1, 3)), 0.0, np.array([0.5]), f)
    np.testing.assert_allclose(f, 0.0, atol=1e-9)
    assert lam.shape == (1,)
    n = np.array([0.0, 0.6, 0.8])
    plane = HardConstraints([OnPlanes([0], (0, 0, 0), n)])
    weight = np.array([0.0, 0.0, -2.0 * G])
    f = weight[None].copy()
    plane.force(np.zeros((1, 3)), np.zeros((1, 3)), 0.0, np.array([0.5]), f)
    np.testing.assert_allclose(f[0], weight - (weight @ n) * n, atol=1e-12)


def test_pins_follow_a_moving_target_and_feedback_pulls_back():
    # A pinned point whose target moves at 2 m/s along y: after each step it is on the target
    # and moves with it. Witkin's feedback (ks, kd) turns a displaced pin into a critically
    # damped return when the projection is not run.
    pins = HardConstraints([Pins([0], (0, 0, 0), (0, 2.0, 0))])
    ode = PointOde([[0, 0, 0]], [[0, 2.0, 0]], [1.0], pins)
    seen = []
    ode.run("RK4", 0.01, 0.5, lambda t, s: seen.append((t, s.x[0].copy(), s.v[0].copy())))
    for t, x, v in seen:
        np.testing.assert_allclose(x, (0, 2.0 * t, 0), atol=1e-9)
        np.testing.assert_allclose(v, (0, 2.0, 0), atol=1e-9)
    w = 20.0
    soft = HardConstraints([Pins([0], (0, 0, 0))], Feedback(w * w, 2 * w))
    ode = PointOde([[0.1, 0, 0]], [[0, 0, 0]], [1.0], soft)
    method = make_integrator("RK4")
    for k in range(100):
        method.step(ode, k * 0.001, 0.001)
    t = 0.1  # x(t) = 0.1 (1 + w t) exp(-w t) for a critically damped return
    np.testing.assert_allclose(ode.x[0, 0], 0.1 * (1 + w * t) * math.exp(-w * t), rtol=1e-6)


def test_large_systems_solve_iteratively_like_small_ones(monkeypatch):
    # The same 40-rod chain's constraint forces from the direct solve and from conjugate
    # gradients (forced by lowering the direct limit) agree.
    rng = np.random.default_rng(3)
    x = _chain(40) + rng.normal(0, 0.01, (41, 3))
    v = rng.normal(0, 1, (41, 3))
    inverse = rng.uniform(0.5, 2, 41)
    rods = Rods(np.arange(1, 41), np.arange(40), np.linalg.norm(x[1:] - x[:-1], axis=1))
    direct = np.zeros((41, 3))
    HardConstraints([rods]).force(x, v, 0.0, inverse, direct)
    monkeypatch.setattr(hard, "DENSE_ROWS", 0)
    iterative = np.zeros((41, 3))
    HardConstraints([rods]).force(x, v, 0.0, inverse, iterative)
    np.testing.assert_allclose(iterative, direct, rtol=1e-8, atol=1e-8)


def test_bad_constraints_are_named():
    with pytest.raises(ValueError, match="joins point 3 to itself"):
        Rods([3], [3], [1.0])
    with pytest.raises(ValueError, match="length must be finite and >= 0"):
        Tethers([0], (0, 0, 0), -1.0)
    with pytest.raises(ValueError, match="normal must not be zero"):
        OnPlanes([0], (0, 0, 0), (0, 0, 0))


def test_hard_particle_links_make_a_rope_that_never_stretches():
    # An emitter moving along x drops one particle a frame, each linked to the previous by a
    # hard link (rods at the distance at birth), under gravity at the product's defaults
    # (symplectic Euler, 2 sub-steps): the free rope falls and folds, and no link ever differs
    # from its length at birth by more than 1e-6 of it; with gravity off, momentum stays.
    for gravity in ((0.0, 0.0, -G), (0.0, 0.0, 0.0)):
        model = particle_model(EmitterSettings("Rope", link=SpringLink(0.0, 0.0, hard=True)))
        state = model.state()
        solver = ParticleSolver(model, substeps=2)
        worst, momentum = 0.0, []
        for f in range(48):
            ef = EmitterFrame(rate=1, speed=1.0 if f % 2 else 0.3, lifetime=1000.0,
                              matrix0=translation(0.1 * f), matrix1=translation(0.1 * (f + 1))
                              ) if f < 20 else EmitterFrame(active=False)
            solver.advance(state, _inputs(f, gravity=gravity, emitters=[ef]))
            if len(state.link_a) > 1:
                a, b = state.index_of(state.link_a), state.index_of(state.link_b)
                length = np.linalg.norm(state.particle_x[a] - state.particle_x[b], axis=1)
                worst = max(worst, float(np.max(np.abs(length / state.link_rest - 1.0))))
            if f >= 20:
                momentum.append((state.particle_mass[:, None] * state.particle_v).sum(axis=0))
        assert len(state.link_a) == 19 and worst < 1e-6
        if not any(gravity):
            np.testing.assert_allclose(momentum, [momentum[0]] * len(momentum), atol=1e-9)
        else:
            assert np.ptp(state.particle_x[:, 2]) > 0.05  # it is a rope, not a rigid rod


def _wire(kind, radius=0.5, m0=None, m1=None):
    from physanim.core.particles import PointConstraint
    rot = np.eye(4)
    rot[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # its z axis along -y: a vertical wire
    return PointConstraint("Wire", kind, rot if m0 is None else m0, rot if m1 is None else m1,
                           radius)


def test_an_emitters_particles_run_on_a_wire_at_the_product_defaults():
    # A particle on a vertical circular wire (an ON_CIRCLE constraint on its emitter), started
    # level with the centre going up at 1 m/s, at the product's defaults (symplectic Euler, 2
    # sub-steps, 24 fps) for 10 s: on the wire to 1e-6 m every frame, and its energy within
    # symplectic Euler's first-order bound (RATTLE: measured 0.05 m g R at h = 1/60 s, it
    # halves with h).
    from physanim.core.particles import EmitterFrame as Frame
    from physanim.tests.core.helpers import place
    model = particle_model(EmitterSettings("Beads"))
    state = model.state()
    place(state, [[0.5, 0.0, 0.0]], [[0.0, 0.0, 1.0]], mass=0.2)
    solver = ParticleSolver(model, substeps=2)
    wire = _wire("ON_CIRCLE")
    e0 = 0.5 * 0.2 * 1.0
    worst_off, worst_energy = 0.0, 0.0
    for f in range(240):
        solver.advance(state, _inputs(f, emitters=[Frame(active=False, constraints=(wire,))]))
        x, v = state.particle_x[0], state.particle_v[0]
        worst_off = max(worst_off, abs(np.linalg.norm(x) - 0.5), abs(x[1]))
        worst_energy = max(worst_energy, abs(0.5 * 0.2 * v @ v + 0.2 * G * x[2] - e0))
    assert worst_off < 1e-6
    assert worst_energy < 0.15 * 0.2 * G * 0.5


def test_particles_born_off_a_moving_plane_are_put_on_it_and_ride_it():
    # An emitter at the origin shoots particles up at 5 m/s and sideways; an ON_PLANE
    # constraint on it (a horizontal plane rising at 1 m/s from z = 1) holds every particle:
    # each is on the plane at every frame (to 1e-9 m), however it was born, and they keep
    # their sideways motion (the constraint removes only the normal part).
    from physanim.core.particles import EmitterFrame as Frame
    model = particle_model(EmitterSettings("Lift", direction="AXIS", axis=(1.0, 0.0, 1.0)))
    state = model.state()
    solver = ParticleSolver(model, substeps=2)
    for f in range(24):
        m0, m1 = translation(0, 0, 1.0 + f * DT), translation(0, 0, 1.0 + (f + 1) * DT)
        plane = _wire("ON_PLANE", m0=m0, m1=m1)
        solver.advance(state, _inputs(f, emitters=[Frame(rate=3, speed=5.0, lifetime=100.0,
                                                         constraints=(plane,))]))
        np.testing.assert_allclose(state.particle_x[:, 2], 1.0 + (f + 1) * DT, atol=1e-9)
        np.testing.assert_allclose(state.particle_v[:, 2], 1.0, atol=1e-9)
    assert state.particle_count > 50 and np.ptp(state.particle_x[:, 0]) > 1.0


# -- beads on a wire of any shape (ON_CURVE: the polyline of a curve object) -----------------

def _curve_wire(p0, p1=None, cyclic=False):
    from physanim.core.particles import PointConstraint
    return PointConstraint("Wire", "ON_CURVE", points0=p0, points1=p0 if p1 is None else p1,
                           cyclic=cyclic)


def _run_bead(wire_at, x0, v0, frames, mass=0.2):
    """One bead on the wire ``wire_at(frame)`` at the product's defaults (symplectic Euler, 2
    sub-steps, 24 fps): its (position, velocity) after each frame."""
    from physanim.core.particles import EmitterFrame as Frame
    from physanim.tests.core.helpers import place
    model = particle_model(EmitterSettings("Beads"))
    state = model.state()
    place(state, [x0], [v0], mass=mass)
    solver = ParticleSolver(model, substeps=2)
    out = []
    for f in range(frames):
        solver.advance(state, _inputs(f, emitters=[Frame(active=False,
                                                         constraints=(wire_at(f),))]))
        out.append((state.particle_x[0].copy(), state.particle_v[0].copy()))
    return out


def _off_polyline(x, pts, cyclic):
    a, b = (pts, np.roll(pts, -1, axis=0)) if cyclic else (pts[:-1], pts[1:])
    d = b - a
    u = np.clip(np.einsum("ij,ij->i", x - a, d) / np.einsum("ij,ij->i", d, d), 0.0, 1.0)
    return float(np.min(np.linalg.norm(x - (a + u[:, None] * d), axis=1)))


def _circle_points(count, radius=0.5):
    a = np.arange(count) * 2.0 * np.pi / count
    return np.column_stack([radius * np.cos(a), np.zeros(count), radius * np.sin(a)])


def test_a_bead_on_a_curve_sampling_a_circle_moves_as_on_the_circle_itself():
    # The vertical wire of the ON_CIRCLE test above, now a closed polyline of 64 points (what a
    # curve object gives), same start, 10 s at the defaults: on the polyline to 1e-6 m, energy
    # within the same first-order bound, and where the exact circle's bead is (to 2 cm: the
    # polyline's corners are 1.2 mm inside the circle). Without the wire's curvature in J'v,
    # the bead would lose speed at every corner (4 pi^2 / 64 of its energy per turn).
    pts = _circle_points(64)
    bead = _run_bead(lambda f: _curve_wire(pts, cyclic=True), [0.5, 0.0, 0.0], [0, 0, 1.0], 240)
    circle = _run_bead(lambda f: _wire("ON_CIRCLE"), [0.5, 0.0, 0.0], [0, 0, 1.0], 240)
    e0 = 0.5 * 0.2 * 1.0
    energy = max(abs(0.5 * 0.2 * v @ v + 0.2 * G * x[2] - e0) for x, v in bead)
    assert max(_off_polyline(x, pts, True) for x, _ in bead) < 1e-6
    assert energy < 0.15 * 0.2 * G * 0.5
    assert max(np.linalg.norm(b[0] - c[0]) for b, c in zip(bead, circle)) < 0.02


def test_a_bead_slides_down_a_straight_wire_at_g_sin_theta():
    # A straight wire of two segments from (0, 0, 1) to (3, 0, 0): sin(theta) = 1/sqrt(10). From
    # rest, symplectic Euler's n steps of h give h^2 a n (n + 1) / 2 exactly (a = g sin theta);
    # that is the closed form 1/2 a t^2 to first order, (n + 1)/n.
    pts = np.array([[0.0, 0.0, 1.0], [1.5, 0.0, 0.5], [3.0, 0.0, 0.0]])
    bead = _run_bead(lambda f: _curve_wire(pts), pts[0], [0.0, 0.0, 0.0], 12)
    n, h, a = 24, DT / 2, G / math.sqrt(10.0)
    travelled = np.linalg.norm(bead[-1][0] - pts[0])
    assert travelled == pytest.approx(h * h * a * n * (n + 1) / 2, rel=1e-9)
    assert travelled == pytest.approx(0.5 * a * (n * h) ** 2, rel=1.0 / n + 1e-9)
    assert max(_off_polyline(x, pts, False) for x, _ in bead) < 1e-9


def test_a_bead_runs_down_a_helix_keeping_its_energy():
    # A helix of three turns (radius 0.5 m, rising 0.3 m a turn) sampled at 301 points, a 3-D
    # curve with curvature and torsion; a bead let go at the top for 4 s runs down it: on the
    # wire to 1e-6 m, energy within 2 % of m g H (first order at h = 1/48 s: measured 0.5 %).
    s = np.linspace(0.0, 6.0 * np.pi, 301)
    pts = np.column_stack([0.5 * np.cos(s), 0.5 * np.sin(s), 0.3 * s / (2.0 * np.pi)])
    bead = _run_bead(lambda f: _curve_wire(pts), pts[-1], [0.0, 0.0, 0.0], 96)
    e0 = 0.2 * G * pts[-1, 2]
    energy = max(abs(0.5 * 0.2 * v @ v + 0.2 * G * x[2] - e0) for x, v in bead)
    assert max(_off_polyline(x, pts, False) for x, _ in bead) < 1e-6
    assert energy < 0.02 * 0.2 * G * 0.9
    assert min(x[2] for x, _ in bead) < 0.3  # it ran down, not stuck


def test_a_moving_wire_carries_its_bead():
    # A horizontal circular wire (64 points) sliding along x at 1 m/s, its bead whirling round it
    # at 1 m/s: on the moving polyline to 1e-6 m at every frame.
    pts = _circle_points(64)[:, [0, 2, 1]]
    move = np.array([1.0, 0.0, 0.0])
    bead = _run_bead(lambda f: _curve_wire(pts + move * f * DT, pts + move * (f + 1) * DT, True),
                     pts[0], [0.0, 1.0, 0.0], 48)
    assert max(_off_polyline(x, pts + move * (f + 1) * DT, True)
               for f, (x, _) in enumerate(bead)) < 1e-6
    assert bead[-1][0][0] > 1.5  # carried along


def test_the_nearest_segment_search_finds_what_a_search_of_every_segment_finds():
    from physanim.core.forces.constraint_rows import _nearest_on_segments
    rng = np.random.default_rng(4)
    pts = np.cumsum(rng.normal(size=(500, 3)), axis=0)
    x = pts[rng.integers(0, 500, 3000)] + rng.normal(scale=2.0, size=(3000, 3))
    a, b = pts[:-1], pts[1:]
    seg, u = _nearest_on_segments(x, a, b)
    d = b - a
    uu = np.clip(np.einsum("rsk,sk->rs", x[:, None] - a[None], d) / np.einsum("sk,sk->s", d, d),
                 0.0, 1.0)
    every = np.linalg.norm(x[:, None] - (a[None] + uu[..., None] * d[None]), axis=2)
    found = np.linalg.norm(x - (a[seg] + u[:, None] * d[seg]), axis=1)
    np.testing.assert_allclose(found, every.min(axis=1), rtol=0, atol=1e-12)
    ranked = np.sort(every, axis=1)
    clear = ranked[:, 1] - ranked[:, 0] > 1e-9  # not at a vertex two segments share
    assert clear.sum() > 1000
    assert np.array_equal(seg[clear], np.argmin(every, axis=1)[clear])


def test_a_wire_with_two_points_at_one_place_is_refused_by_name():
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match='constraint "Wire".*points 1 and 2 are at the same'):
        _curve_wire(pts)
    with pytest.raises(ValueError, match="changed its number of points from 3 to 2"):
        _curve_wire(pts + [[0, 0, 0], [0, 0, 0], [1, 0, 0]], pts[:2])
