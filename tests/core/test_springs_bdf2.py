"""BDF2 for spring meshes (:mod:`physanim.core.springs.bdf2`): against the textbook recurrence on
the linear oscillator, its order of convergence, its damping against backward Euler's, and the
steps it must take as backward Euler (contacts, coupling, a changed sub-step).

Oscillator: two equal masses on one spring along x (no gravity, damping, shear, bending or drag)
move only in q = |x1 - x0| - r, q'' = -omega^2 q: linear, so BDF2 on it is a linear recurrence
the test computes on its own (first step backward Euler: no history yet).
"""
from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

from physanim.core.contact import ColliderFrame
from physanim.core.springs import (SpringFrameInputs, SpringMeshBuilder, SpringMeshSettings,
                                   SpringMeshSolver)
from physanim.core.springs.bdf2 import BDF2
from physanim.core.springs.model import Attachment
from physanim.core.springs.implicit import BaraffWitkin
from physanim.tests.core.helpers import grid

MASS = 2.0  # [kg], 1 kg per vertex: reduced mass 0.5 kg
MU = 0.25 * MASS
OMEGA = 2.0 * math.pi  # [rad/s]: a 1 s period
K = MU * OMEGA ** 2
STRETCH = 0.1  # [m]


def _pair(integrator: str, h: float):
    settings = SpringMeshSettings("Pair", mass=MASS, stiffness=K, damping=0.0,
                                  shear_stiffness=0.0, bend_mode="NONE", drag=0.0)
    model = SpringMeshBuilder(settings, [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], [[0, 1]],
                              np.zeros((0, 3))).finalize(1)
    return model, SpringMeshSolver(model, integrator, 1, frame_dt=h, frame=1)


def _oscillate(integrator: str, h: float, steps: int) -> np.ndarray:
    """(steps + 1, 2) [q, q'] after every step from q = STRETCH at rest."""
    model, solver = _pair(integrator, h)
    state = model.state()
    state.x[1, 0] += STRETCH
    out = [(STRETCH, 0.0)]
    for k in range(steps):
        solver.advance(state, SpringFrameInputs(k + 1, k * h, h, gravity=(0.0, 0.0, 0.0)))
        assert np.all(state.x[:, 1:] == 0.0)  # on the axis: the force is linear in q
        out.append((state.x[1, 0] - state.x[0, 0] - 1.0, state.v[1, 0] - state.v[0, 0]))
    return np.array(out)


def _recurrence(h: float, steps: int) -> np.ndarray:
    """BDF2 on u' = J u, u = [q, q'], started by one backward Euler step, computed here."""
    jac = np.array([[0.0, 1.0], [-OMEGA ** 2, 0.0]])
    u = [np.array([STRETCH, 0.0])]
    u.append(np.linalg.solve(np.eye(2) - h * jac, u[0]))
    step = np.linalg.inv(np.eye(2) - (2.0 * h / 3.0) * jac)
    while len(u) <= steps:
        u.append(step @ ((4.0 * u[-1] - u[-2]) / 3.0))
    return np.array(u)


@pytest.mark.parametrize("per_period", [24, 200])
def test_bdf2_is_the_textbook_recurrence_on_the_oscillator(per_period):
    """Three periods. The implicit solve here is direct (two vertices), so each step is exact to
    rounding except for CG's accepted residual (1e-3 of the right-hand side): allowance 1e-3 of
    the amplitude per step's change, summed over the run."""
    h = 1.0 / per_period
    steps = 3 * per_period
    got = _oscillate("BDF2", h, steps)
    want = _recurrence(h, steps)
    change = np.abs(np.diff(want[:, 0])).sum()
    assert np.abs(got[:, 0] - want[:, 0]).max() <= 1e-3 * change + 1e-12
    assert np.abs(got[:, 1] - want[:, 1]).max() <= 1e-3 * OMEGA * change + 1e-12


def test_bdf2_converges_at_second_order_backward_euler_at_first():
    """Error at t = 1 s against STRETCH cos(omega t) for h and h / 2: BDF2's error ratio near 4
    (second order), backward Euler's near 2."""
    def error(integrator, per_period):
        q = _oscillate(integrator, 1.0 / per_period, per_period)[-1, 0]
        return abs(q - STRETCH * math.cos(OMEGA))
    bdf = error("BDF2", 100) / error("BDF2", 200)
    euler = error("IMPLICIT", 100) / error("IMPLICIT", 200)
    assert 3.5 < bdf < 4.5, bdf
    assert 1.7 < euler < 2.3, euler


def test_bdf2_damps_a_resolved_swing_far_less_than_backward_euler():
    """At 24 steps per period (a cloth swinging once a second at one step per frame) backward
    Euler keeps |1 / (1 - i omega h)|^24 = 0.45 of the amplitude per period; BDF2's principal
    root keeps 0.98 (both read off the characteristic equations: z = omega h = 0.26)."""
    z = 2.0 * math.pi / 24
    be = abs(1.0 / (1.0 - 1j * z)) ** 24
    roots = np.roots([1.5 - 1j * z, -2.0, 0.5])  # (3/2 - i z) r^2 - 2 r + 1/2 = 0
    bdf = max(abs(roots)) ** 24
    assert be < 0.63 and bdf > 0.97
    for integrator, keep in (("IMPLICIT", be), ("BDF2", bdf)):
        u = _oscillate(integrator, 1.0 / 24, 24 * 6)
        amplitude = np.hypot(u[:, 0], u[:, 1] / OMEGA)
        ratio = amplitude[24 * 5] / amplitude[24 * 4]  # one period, after the start-up
        assert ratio == pytest.approx(keep, rel=0.01), integrator


def _cloth(n: int = 12, pins: bool = True, **settings):
    x, edges, tris, ls, lt, lv = grid(n, n, 1.0)
    x = np.stack([x[:, 0], x[:, 1], np.full(len(x), 1.0)], axis=1)
    weight = np.zeros(len(x))
    if pins:
        weight[[0, n - 1]] = 1.0
    return SpringMeshBuilder(SpringMeshSettings("Cloth", **settings), x, edges, tris, ls, lt,
                             lv, pin_weight=weight).finalize(1)


def _frames(solver, state, first, last, colliders=()):
    for f in range(first, last + 1):
        solver.advance(state, SpringFrameInputs(f, (f - 1) / 24, 1 / 24, gravity=(0, 0, -9.81),
                                                colliders=list(colliders)))


def test_a_pinned_cloth_takes_bdf2_steps_and_swings_more_than_with_backward_euler():
    """The default cloth hanging from two corners, let swing for 4 s: BDF2 steps throughout
    (after the first), pins on their targets, and at the same two sub-steps it keeps more of the
    swing's kinetic energy than backward Euler (its damping is the springs' own, not the
    method's)."""
    energy = {}
    for integrator in ("IMPLICIT", "BDF2"):
        model = _cloth()
        solver = SpringMeshSolver(model, integrator, 2, frame_dt=1 / 24, frame=1)
        state = model.state()
        _frames(solver, state, 1, 96)
        assert np.array_equal(state.x[[0, 11]], model.rest_x[[0, 11]])
        energy[integrator] = 0.5 * np.sum(model.vertex_mass[:, None] * state.v ** 2)
        if integrator == "BDF2":
            assert isinstance(solver.integrator, BDF2) and solver.integrator.last_second_order
    assert energy["BDF2"] > 2.0 * energy["IMPLICIT"], energy


def test_bdf2_at_its_defaults_drops_a_cloth_onto_the_ground_and_it_rests():
    """Only the integrator chosen: the cloth falls, lands (bouncing at the ground's default
    restitution), and lies still on it, nothing below it. Its steps are BDF2 ones, contacts
    and friction included, but for the first and those right after a landing changed every
    vertex's velocity (their history starts again: a backward Euler step)."""
    model = _cloth(pins=False)
    solver = SpringMeshSolver(model, "BDF2", 2, frame_dt=1 / 24, frame=1)
    state = model.state()
    ground = ColliderFrame("Ground", "PLANE", np.diag([10.0, 10.0, 1.0, 1.0]),
                           np.diag([10.0, 10.0, 1.0, 1.0]))
    second = []
    for f in range(1, 73):
        _frames(solver, state, f, f, [ground])
        second.append(solver.integrator.last_second_order)
        assert state.x[:, 2].min() > -1e-6
    assert all(second[-36:]) and sum(second) >= len(second) - 5, second
    assert np.abs(state.v).max() < 1e-3 and np.ptp(state.x[:, 2]) < 1e-3


def test_held_vertices_end_a_bdf2_step_where_backward_euler_would_put_them():
    """The filter of a BDF2 step (from an extrapolated state) against backward Euler's from the
    real one, on a real step of a cloth hanging from two corners onto the ground (pins, pressed
    and stuck vertices): every direction both prescribe ends at the same place, x^ + h^ w' =
    x0 + h w, whatever the history."""
    model = _cloth(n=10)
    solver = SpringMeshSolver(model, "BDF2", 1, frame_dt=1 / 24, frame=1)
    stepper = solver.integrator
    seen = []
    step = stepper.step

    def record(system, t, h):
        if len(system.contact):
            seen.append((system, t, h, system.state.x.copy(), system.state.v.copy()))
        return step(system, t, h)
    stepper.step = record
    state = model.state()
    ground = ColliderFrame("Ground", "PLANE", np.diag([10.0, 10.0, 1.0, 1.0]),
                           np.diag([10.0, 10.0, 1.0, 1.0]))
    state.x[:, 2] -= 0.8  # most of the cloth comes to lie on the ground as it swings down
    for f in range(1, 25):
        _frames(solver, state, f, f, [ground])
    system, t, h, x0, v0 = max(seen, key=lambda s: len(s[0].contact))
    assert (~system.free).sum() == 2
    rng = np.random.default_rng(3)
    before = (x0 - h * v0 + rng.normal(0, 1e-6, x0.shape), v0 + rng.normal(0, 1e-3, x0.shape))
    x_hat, v_hat, h_hat = (4 * x0 - before[0]) / 3, (4 * v0 - before[1]) / 3, 2 * h / 3
    be = BaraffWitkin._constraints(system, t, h, v0, system.forces_at(t, x0, v0))
    stepper._start = (x0, v0, h, x_hat)
    bdf = stepper._constraints(system, t + h / 3, h_hat, v_hat,
                               system.forces_at(t + h / 3, x_hat, v_hat))
    stepper._start = None
    end_be, end_bdf = x0 + h * (v0 + be.given), x_hat + h_hat * (v_hat + bdf.given)
    fixed = (be.free_scale[:, 0] == 0.0) & (bdf.free_scale[:, 0] == 0.0)
    assert fixed.sum() >= 2
    np.testing.assert_allclose(end_bdf[fixed], end_be[fixed], rtol=0, atol=1e-12)
    both, i_be, i_bdf = np.intersect1d(be.pressed, bdf.pressed, return_indices=True)
    assert len(both), (len(be.pressed), len(bdf.pressed), len(system.contact))
    n = be.normal[i_be]
    np.testing.assert_allclose(np.einsum("ij,ij->i", end_bdf[both], n),
                               np.einsum("ij,ij->i", end_be[both], n), rtol=0, atol=1e-12)


def test_a_bdf2_bake_resumed_from_a_pickle_is_the_same_to_the_bit():
    model = _cloth()
    solver = SpringMeshSolver(model, "BDF2", 2, frame_dt=1 / 24, frame=1)
    state = model.state()
    _frames(solver, state, 1, 10)
    copy_solver, copy_state = pickle.loads(pickle.dumps((solver, state)))
    _frames(solver, state, 11, 20)
    _frames(copy_solver, copy_state, 11, 20)
    assert np.array_equal(state.x, copy_state.x) and np.array_equal(state.v, copy_state.v)


def test_bdf2_restarts_its_history_where_the_state_was_changed_between_steps():
    """A vertex moved between two steps (as pins, self-collision or strain limiting do) takes a
    backward Euler step at its velocity and the last step's velocity change as its history;
    the others keep theirs. Checked on the history the stepper takes: x_-1 = x0 - h v0 and
    v_-1 = v0 - dv for the moved vertex only."""
    model = _cloth(pins=False)
    solver = SpringMeshSolver(model, "BDF2", 1, frame_dt=1 / 24, frame=1)
    state = model.state()
    _frames(solver, state, 1, 3)
    stepper = solver.integrator
    past = stepper.history
    state.x[5, 2] += 1e-3
    x0, v0 = state.x.copy(), state.v.copy()
    before = stepper._before(past.t + past.h, past.h, x0, v0)
    h = past.h
    dv = past.end[1][5] - past.start[1][5]
    assert np.linalg.norm(dv) > 0.01  # (falling: g h = 0.41 m/s)
    assert np.array_equal(before[0][5], x0[5] - h * v0[5] + 0.5 * h * dv)
    assert np.array_equal(before[1][5], v0[5] - dv)
    others = np.arange(len(x0)) != 5
    assert np.array_equal(before[0][others], past.start[0][others])
    assert np.array_equal(before[1][others], past.start[1][others])
    # a step of another length, or from another time, is backward Euler's
    fresh = BDF2()
    fresh.history = past
    assert fresh._before(past.t + past.h, 0.5 * past.h, x0, v0) is None


def test_vertices_whose_history_restarts_every_step_still_fall_at_g():
    """Free fall, one step per frame, every vertex but one moved by a rounding step after each
    frame (as self-collision or strain limiting may do): their history starts again every
    step, and still their velocity after 1 s is -g t (a restart at constant velocity would let
    them fall at 2/3 g), as the untouched vertex's is. (No air drag: then gravity is the only
    force on the undeformed cloth, and BDF2 is exact for it; allowance: the implicit solve's
    relative tolerance, 1e-3.)"""
    model = _cloth(n=6, pins=False, drag=0.0)
    solver = SpringMeshSolver(model, "BDF2", 1, frame_dt=1 / 24, frame=1)
    state = model.state()
    for f in range(1, 25):
        _frames(solver, state, f, f)
        state.x[1:] = np.nextafter(state.x[1:], np.inf)
        assert f == 1 or solver.integrator.last_second_order
    np.testing.assert_allclose(state.v[:, 2], -9.81, rtol=BDF2.TOLERANCE)


def test_a_cloth_on_one_way_attachments_takes_bdf2_steps():
    """Attached to nothing (held in place, as pins) or to an animated object, a mesh exchanges
    no impulse with a body: its steps are BDF2 ones."""
    n = 8
    x, edges, tris, ls, lt, lv = grid(n, n, 1.0)
    x = np.stack([x[:, 0], x[:, 1], np.full(len(x), 1.0)], axis=1)
    builder = SpringMeshBuilder(SpringMeshSettings("Cloth"), x, edges, tris, ls, lt, lv)
    builder.add_attachment(Attachment([0, n - 1], None))
    model = builder.finalize(1)
    solver = SpringMeshSolver(model, "BDF2", 2, frame_dt=1 / 24, frame=1)
    state = model.state()
    second = []
    for f in range(1, 25):
        _frames(solver, state, f, f)
        second.append(solver.integrator.last_second_order)
    assert all(second)
    np.testing.assert_allclose(state.x[[0, n - 1]], model.rest_x[[0, n - 1]], atol=1e-9)


def test_bdf2_keeps_a_stiff_grid_bounded_at_one_step_per_frame():
    """A-stability on a stiff, nonlinear mesh: the 10 x 10 grid of k = 1e5 N/m of the implicit
    Euler test (omega h of an edge spring 186) at one step per frame stays near its springs'
    rest lengths, hangs from its corners and loses energy overall (BDF2 need not lose it in
    every frame)."""
    from physanim.tests.core.test_springs_implicit import (ENERGY_SCALE, PINNED, SIZE,
                                                           _energy, _inputs, _stiff_grid)
    model = _stiff_grid()
    solver = SpringMeshSolver(model, "BDF2", 1, frame_dt=1 / 24, frame=1)
    state = model.state()
    start = _energy(model, state)
    for frame in range(1, 101):
        solver.advance(state, _inputs(frame))
        assert frame == 1 or solver.integrator.last_second_order
        length = np.linalg.norm(state.x[model.spring_i] - state.x[model.spring_j], axis=1)
        assert np.all(length < 1.05 * model.spring_rest)
        reach = np.linalg.norm(state.x[:, None, :] - model.rest_x[None, PINNED], axis=2).min(1)
        assert np.all(reach < 1.01 * np.hypot(SIZE, SIZE))
    assert _energy(model, state) < start - 0.3 * ENERGY_SCALE


def test_bdf2_steps_by_whether_the_mesh_exchanges_impulses_with_a_body():
    """A rope holding a box (two-way: the box and the rope exchange impulses) takes backward
    Euler steps; a cloth with a rigid body in the world that it does not touch takes BDF2
    steps."""
    from physanim.tests.core.test_coupling import DT, box, coupled, rope, run
    builder = rope(11)
    builder.add_attachment(Attachment([10], "Box"))
    world, rstate, model, mstate = coupled(builder, box("Box", (0.1, 0.1, 0.1), (0.0, 0.0, 0.9),
                                                       mass=1.0), integrator="BDF2")
    stepper = world.systems[1].solver.integrator
    steps = []
    run(world, 24, each=lambda f: steps.append(stepper.last_second_order))
    assert isinstance(stepper, BDF2) and not any(steps)
    assert np.isfinite(mstate.x).all() and 0.5 < rstate.body_x[0, 2] < 1.0  # it hangs

    x, edges, tris, ls, lt, lv = grid(6, 6, 1.0)
    x = np.stack([x[:, 0], x[:, 1], np.full(len(x), 1.0)], axis=1)
    weight = np.zeros(len(x))
    weight[[0, 5]] = 1.0
    builder = SpringMeshBuilder(SpringMeshSettings("Cloth"), x, edges, tris, ls, lt, lv,
                                pin_weight=weight)
    world, rstate, model, mstate = coupled(builder, box("Far", (0.1, 0.1, 0.1), (5.0, 0.0, 3.0),
                                                       mass=1.0), integrator="BDF2")
    stepper = world.systems[1].solver.integrator
    steps = []
    run(world, 12, each=lambda f: steps.append(stepper.last_second_order))
    assert all(steps[1:]) and rstate.body_x[0, 2] < 3.0 - 0.5 * 9.81 * (11 * DT) ** 2 * 0.9
