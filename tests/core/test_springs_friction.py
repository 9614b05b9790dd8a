"""Coulomb friction on spring meshes (the implicit stepper): a cloth lying on a slope steeper
than its friction angle slides at the Coulomb rate, g (sin theta - mu cos theta); on a slope
shallower than it, static friction holds it where it lies, and a cloth at rest on a collider
costs no linear solve (its vertices are held as pins are)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core.contact import ColliderFrame
from physanim.core.springs import (SpringFrameInputs, SpringMeshBuilder, SpringMeshSettings,
                                   SpringMeshSolver)
from physanim.core.springs.implicit import BaraffWitkin
from physanim.tests.core.helpers import grid as _grid

DT = 1.0 / 24.0
G = 9.81
THETA = math.radians(30.0)


def _tilt() -> np.ndarray:
    """The slope's frame: the ground turned THETA about x (its normal is the third column)."""
    c, s = math.cos(THETA), math.sin(THETA)
    m = np.eye(4)
    m[1:3, 1:3] = [[c, -s], [s, c]]
    return m


def _on_slope(mu: float):
    """A 0.4 m cloth patch (7 x 7 vertices) lying on a 30 degree slope of friction ``mu``, no
    air drag (nothing but gravity, the slope and the cloth's own springs act on it)."""
    m = _tilt()
    x, edges, tris, ls, lt, lv = _grid(7, 7, 0.4)
    x = (x - [0.2, 0.2, 0.0]) @ m[:3, :3].T
    settings = SpringMeshSettings("Patch", mass=0.2, stiffness=2000.0, damping=2.0,
                                  shear_stiffness=500.0, bend_stiffness=0.01, drag=0.0)
    model = SpringMeshBuilder(settings, x, edges, tris, ls, lt, lv).finalize(1)
    slope = ColliderFrame("Slope", "HALF_SPACE", m, m, restitution=0.0, friction=mu)
    return model, slope, m[:3, 2], -m[:3, 1]  # normal, downhill


def _run(model, slope, frames: int, integrator: str = "IMPLICIT"):
    solver = SpringMeshSolver(model, integrator, 2, frame_dt=DT, frame=1)
    state = model.state()
    for frame in range(1, frames + 1):
        solver.advance(state, SpringFrameInputs(frame, frame * DT, DT, colliders=[slope]))
        yield frame, state, solver


@pytest.mark.parametrize("integrator", ["IMPLICIT", "BDF2"])
def test_cloth_on_a_slope_steeper_than_its_friction_slides_at_the_coulomb_rate(integrator):
    """(BDF2: its steps on the slope are second-order ones, contacts and friction included.)"""
    mu = 0.2  # < tan 30 = 0.577
    model, slope, normal, downhill = _on_slope(mu)
    speed = {}
    for frame, state, solver in _run(model, slope, 36, integrator):
        assert (state.x @ normal).min() >= -1e-6
        speed[frame] = float(state.v.mean(axis=0) @ downhill)
        if integrator == "BDF2" and frame > 1:
            assert solver.integrator.last_second_order, frame
    expected = G * (math.sin(THETA) - mu * math.cos(THETA))
    measured = (speed[36] - speed[12]) / (24 * DT)
    assert measured == pytest.approx(expected, rel=0.02)


@pytest.mark.parametrize("integrator", ["IMPLICIT", "BDF2"])
def test_cloth_on_a_slope_shallower_than_its_friction_stays_where_it_lies(integrator):
    mu = 0.8  # > tan 30
    model, slope, normal, downhill = _on_slope(mu)
    centre = None
    for frame, state, solver in _run(model, slope, 72, integrator):
        assert (state.x @ normal).min() >= -1e-6
        if frame == 12:
            centre = state.x.mean(axis=0)
        if frame > 12:  # settled: held by static friction, no solve left to do
            assert np.linalg.norm(state.x.mean(axis=0) - centre) < 1e-4
            assert solver.integrator.last_iterations == 0
    assert np.abs(state.v).max() < 1e-6
    # where it lies: it slid no more than it could in the one sub-step before friction held it
    assert abs((centre - model.rest_x.mean(axis=0)) @ downhill) < 1e-3


def test_friction_far_smaller_than_the_rest_of_the_step_still_stops_a_slide():
    """One mesh of two parts: a 1 m sheet 1 m up, stretched to twice its size (its springs'
    forces make the step's right-hand side large), and a 10 cm patch sliding on the ground
    at 5 cm/s, its friction 0.5. Friction can take mu g h = 0.1 m/s from it in each sub-step,
    so the patch stops in the first one. (Friction's solve was judged against the whole
    step's right-hand side, and an impulse below that tolerance was dropped whole: the patch
    slid on at 4.98 cm/s; a towel lying in folds slid across the floor at 10 cm/s.)"""
    xa, ea, ta, *_ = _grid(10, 10, 1.0)
    xb, eb, tb, *_ = _grid(2, 2, 0.1)
    n = len(xa)
    x = np.concatenate([xa + [0.0, 0.0, 1.0], xb + [2.0, 0.0, 0.0]])
    model = SpringMeshBuilder(SpringMeshSettings("Two"), x, np.concatenate([ea, eb + n]),
                              np.concatenate([ta, tb + n])).finalize(1)
    state = model.state()
    state.x[:n, :2] *= 2.0
    state.v[n:, 0] = 0.05
    ground = ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4), friction=0.5)
    solver = SpringMeshSolver(model, "IMPLICIT", 2, frame_dt=DT, frame=1)
    solver.advance(state, SpringFrameInputs(1, DT, DT, colliders=[ground]))
    assert np.abs(state.x[n:, 2]).max() < 1e-6  # still lying on the ground
    assert np.abs(state.v[n:]).max() < 1e-3


def test_cloth_at_rest_on_the_ground_at_the_defaults_costs_no_solve():
    """The defaults (a collider's friction, the mesh's settings) on the common case: a cloth
    dropped flat onto the ground comes to rest, and from then on its steps solve nothing."""
    x, edges, tris, ls, lt, lv = _grid(9, 9, 1.0)
    x = x - [0.5, 0.5, -0.3]
    model = SpringMeshBuilder(SpringMeshSettings("Sheet"), x, edges, tris, ls, lt,
                              lv).finalize(1)
    ground = ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4))
    iterations = []
    for frame, state, solver in _run(model, ground, 48):
        assert state.x[:, 2].min() >= -1e-6
        if frame > 24:
            iterations.append(solver.integrator.last_iterations)
    assert state.x[:, 2].max() < 0.01
    assert np.abs(state.v).max() < 1e-6
    assert max(iterations) == 0



def test_a_newton_iteration_whose_start_solves_the_step_builds_nothing():
    """A cloth at the defaults lying 2 mm inside the ground: the contacts push it out, its
    steps gain that energy, and a Newton iteration looks again at each one's end. Where the
    end already solves the step, no linearisation, matrix or preconditioner is built only for
    a solve that takes no CG iteration (40 % of a cloth's linearisations on Suzanne)."""
    x, edges, tris, ls, lt, lv = _grid(11, 11, 1.0)
    model = SpringMeshBuilder(SpringMeshSettings("Sheet"), x - [0.5, 0.5, 0.0], edges, tris,
                              ls, lt, lv).finalize(1)
    m = np.eye(4)
    m[2, 3] = 0.002
    ground = ColliderFrame("Ground", "HALF_SPACE", m, m)
    solver = SpringMeshSolver(model, "IMPLICIT", 2, frame_dt=DT, frame=1)
    integrator = solver.integrator
    later, checks = [], []
    solve, newton_rhs = integrator._solve, integrator._newton_rhs

    def counted(linear, known, constraints, start, floor):
        out = solve(linear, known, constraints, start, floor)
        if not np.any(known) and start is None:  # a later Newton iteration's solve
            later.append(out[1])
        return out

    def checked(*args):
        checks.append(1)
        return newton_rhs(*args)

    integrator._solve, integrator._newton_rhs = counted, checked
    state = model.state()
    for frame in range(1, 97):
        solver.advance(state, SpringFrameInputs(frame, frame * DT, DT, colliders=[ground]))
    assert checks, "no step looked again at its end: the scene does not test it"
    assert all(iterations > 0 for iterations in later)
    assert state.x[:, 2].min() >= 0.002 - 1e-6  # pushed out onto the surface


@pytest.mark.parametrize("preconditioner", BaraffWitkin.PRECONDITIONERS)
def test_vertices_static_friction_cannot_hold_slide_at_the_coulomb_rate_from_the_first_step(
        monkeypatch, preconditioner):
    """The patch at rest on a slope steeper than its friction angle: each vertex starts held by
    static friction, whose holding impulse, m g h sin theta along the slope, leaves the cone
    (mu m g h cos theta). The step cuts it back to the cone's edge and lets the rest go in the
    friction pass (every vertex was held: the pass builds the matrix and a preconditioner for
    the looser filter): after one step every vertex slides at g h (sin theta - mu cos theta),
    within the solve's tolerance, and the step's linear system was solved once (a second solve
    of the step with them sliding, then the friction pass, took a tenth of a cloth's drape
    over Suzanne)."""
    mu = 0.2
    model, slope, normal, downhill = _on_slope(mu)
    newtons = []  # per step, its linear solves
    newton, step = BaraffWitkin._newton, BaraffWitkin._step_impl

    def counted(self, *a, **k):
        newtons[-1] += 1
        return newton(self, *a, **k)

    def stepped(self, *a, **k):
        newtons.append(0)
        return step(self, *a, **k)
    monkeypatch.setattr(BaraffWitkin, "_newton", counted)
    monkeypatch.setattr(BaraffWitkin, "_step_impl", stepped)
    state = model.state()
    solver = SpringMeshSolver(model, "IMPLICIT", 1, frame_dt=DT, frame=1)  # (one step)
    solver.integrator = BaraffWitkin(preconditioner=preconditioner)
    solver.advance(state, SpringFrameInputs(1, DT, DT, colliders=[slope]))
    speed = G * DT * (math.sin(THETA) - mu * math.cos(THETA))
    assert newtons and set(newtons) == {1}
    tolerance = 10 * solver.integrator.tolerance * G * DT
    np.testing.assert_allclose(state.v, np.outer(np.full(len(state.v), speed), downhill),
                               rtol=0.0, atol=tolerance)
    assert (state.x @ normal).min() >= -1e-9


@pytest.mark.parametrize("preconditioner", BaraffWitkin.PRECONDITIONERS)
def test_the_friction_pass_letting_slipping_vertices_go_keeps_the_steps_preconditioner(
        monkeypatch, preconditioner):
    """Half of the patch at rest on a slope steeper than its friction angle, the other half
    2 cm above it: the lying vertices start held by static friction, which cannot hold them,
    and the friction pass lets them go, reusing the step's preconditioner (built for the
    tighter filter; SPD on the whole space) with its blocks at them loosened. It ends where a
    friction pass with a preconditioner built afresh for the looser filter ends, within the
    solve's tolerance."""
    from physanim.core.springs import implicit

    loosened = implicit.loosened

    def one_frame(fresh: bool):
        model, slope, normal, downhill = _on_slope(0.2)
        state = model.state()
        state.x = state.x + np.where((state.x @ downhill)[:, None] < 0.0, 0.02 * normal, 0.0)
        integrator, calls = BaraffWitkin(preconditioner=preconditioner), []

        def kept_or_fresh(first, constraints, released):
            if first[2] is None or first[3] is None or not len(released):
                return first
            calls.append(1)
            if not fresh:
                return loosened(first, constraints, released)
            sliding = constraints.sliding
            filtered = BaraffWitkin._filtered(first[2], constraints.free,
                                              constraints.pressed[sliding],
                                              constraints.normal[sliding])
            return (*first[:3], integrator._preconditioner(filtered, constraints.free))
        monkeypatch.setattr(implicit, "loosened", kept_or_fresh)
        solver = SpringMeshSolver(model, "IMPLICIT", 1, frame_dt=DT, frame=1)  # (one step)
        solver.integrator = integrator
        solver.advance(state, SpringFrameInputs(1, DT, DT, colliders=[slope]))
        return state.v.copy(), len(calls)

    v_kept, kept = one_frame(fresh=False)
    v_fresh, fresh = one_frame(fresh=True)
    assert kept and fresh
    dv = np.linalg.norm(v_fresh)  # (from rest: the frame's velocity change)
    assert np.linalg.norm(v_kept - v_fresh) <= 10 * BaraffWitkin.TOLERANCE * dv
    assert not np.array_equal(v_kept, v_fresh)  # two solves, each within the tolerance


@pytest.mark.parametrize("preconditioner", BaraffWitkin.PRECONDITIONERS)
def test_the_friction_pass_preconditions_its_let_go_vertices_as_their_new_filter(

        monkeypatch, preconditioner):
    """Half of the patch at rest on a slope steeper than its friction angle, the other half 2 cm
    above it: the friction pass's preconditioner for the lying vertices let slide (the first
    solve's, built with them held: the identity on them) gets, at those vertices, the inverse
    diagonal blocks of the looser filter's matrix S A S + (I - S) — exactly a fresh filter's —
    and keeps every other block. (Measured on the Suzanne drape: a re-solve took 52 CG
    iterations with the identity there, 43 so, 42 with a preconditioner built afresh.)"""
    from physanim.core.springs import implicit
    from physanim.core.transforms import inverse3

    loosened, seen = implicit.loosened, []

    def kept(first, constraints, released):
        out = loosened(first, constraints, released)
        seen.append((first, constraints, released, out))
        return out

    def inverses(precondition):
        return precondition.inverses[0] if preconditioner == "MULTIGRID" else \
            precondition.inverse

    monkeypatch.setattr(implicit, "loosened", kept)
    model, slope, normal, downhill = _on_slope(0.2)
    state = model.state()
    state.x = state.x + np.where((state.x @ downhill)[:, None] < 0.0, 0.02 * normal, 0.0)
    solver = SpringMeshSolver(model, "IMPLICIT", 1, frame_dt=DT, frame=1)
    solver.integrator = BaraffWitkin(preconditioner=preconditioner)
    solver.advance(state, SpringFrameInputs(1, DT, DT, colliders=[slope]))
    changed = [call for call in seen if call[3] is not call[0]]  # (with a matrix)
    assert changed
    first, constraints, released, out = changed[-1]
    assert len(released)
    matrix = first[2]
    sliding = constraints.sliding
    fresh = BaraffWitkin._filtered(matrix, constraints.free, constraints.pressed[sliding],
                                   constraints.normal[sliding])
    np.testing.assert_allclose(inverses(out[3])[released],
                               inverse3(fresh.diagonal())[released], rtol=1e-12, atol=0.0)
    others = np.setdiff1d(np.arange(len(state.x)), released)
    np.testing.assert_array_equal(inverses(out[3])[others], inverses(first[3])[others])


def test_a_friction_solve_starts_from_the_last_one(monkeypatch):
    """Friction's solve after each implicit step (the mesh taking the sliding vertices'
    friction as a whole) starts from the last friction solve's correction: a sheet landing on
    its edge and folding over on the ground slides from one step to the next much as before.
    Each friction solve is run twice here: the first takes its iterations (from the last
    step's correction), the second, starting from the first's answer, one, and ends within
    the solve's tolerance of it. (Started from zero, friction's solves in the self-collision
    benchmark took 35 iterations on average, from the last one 26.)"""
    from physanim.core.springs.implicit import BaraffWitkin

    friction = BaraffWitkin._apply_friction
    solves = []

    def twice(self, *a):
        first = friction(self, *a)
        again = friction(self, *a)
        solves.append((first, again))
        return again
    monkeypatch.setattr(BaraffWitkin, "_apply_friction", twice)
    x, edges, tris, *_ = _grid(15, 15, 1.0)
    x = np.stack([x[:, 0] - 0.5, 0.05 * x[:, 1], x[:, 1] + 0.3], axis=1)  # leaning 3 degrees
    model = SpringMeshBuilder(SpringMeshSettings("Sheet"), x, edges, tris).finalize(1)
    ground = ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4), friction=0.5)
    solver = SpringMeshSolver(model, "IMPLICIT", 2, frame_dt=DT, frame=1)
    state = model.state()
    for frame in range(1, 13):
        solver.advance(state, SpringFrameInputs(frame, frame * DT, DT, gravity=(0.0, 0.0, -G),
                                                colliders=[ground]))
    solved = [(first, again) for first, again in solves if first[1] > 1]
    assert len(solved) >= 5
    for (v1, _, _), (v2, again, _) in solved:
        assert again == 1
        assert np.abs(v2 - v1).max() <= 10 * solver.integrator.tolerance * np.abs(v1).max()
