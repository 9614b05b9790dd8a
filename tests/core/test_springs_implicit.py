"""Stiff spring meshes: implicit Euler (Baraff-Witkin) at one step per frame, and the up-front
stability check of explicit integrators on the same mesh.

Scene: a 10 x 10 grid, 1 m square, total mass 1 kg (0.01 kg per vertex), k = 1e5 N/m edges,
5e4 N/m shear springs, angular bending, pinned at its two corners at y = 1, falling under
gravity at 24 fps: omega h of one edge spring is sqrt(2k/m) h = 4472 * 0.0417 = 186.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from physanim.core.contact import ColliderFrame
from physanim.core.errors import PhysanimError
from physanim.core.springs import (SpringFrameInputs, SpringMeshBuilder, SpringMeshSettings,
                                   SpringMeshSolver, topology)
from physanim.core.springs.implicit import BaraffWitkin
from physanim.tests.core.helpers import grid as _grid

G = 9.81
FPS = 24
N = 10
K = 1e5
MASS = 1.0
SIZE = 1.0
ENERGY_SCALE = MASS * G * SIZE  # [J]: the potential energy the grid can lose by falling


PINNED = [N * (N - 1), N * N - 1]  # the corners at y = SIZE


def _stiff_grid(name: str = "Sheet"):
    x, edges, tris, ls, lt, lv = _grid(N, N, SIZE)
    pin = np.zeros(N * N)
    pin[PINNED] = 1.0
    settings = SpringMeshSettings(name, mass=MASS, stiffness=K, damping=1.0,
                                  shear_stiffness=K / 2, shear_damping=0.5, bend_mode="ANGULAR")
    return SpringMeshBuilder(settings, x, edges, tris, ls, lt, lv, pin_weight=pin).finalize(1)


def _energy(model, state) -> float:
    """Kinetic + gravitational + spring + bending energy [J] (drag and dampers only remove)."""
    m = model.vertex_mass
    kinetic = 0.5 * np.sum(m * np.sum(state.v ** 2, axis=1))
    gravity = G * np.sum(m * state.x[:, 2])
    length = np.linalg.norm(state.x[model.spring_i] - state.x[model.spring_j], axis=1)
    springs = 0.5 * np.sum(model.spring_stiffness * (length - model.spring_rest) ** 2)
    turn = topology.dihedral_angles(state.x, model.hinge) - model.hinge_rest
    bending = 0.5 * model.settings.bend_stiffness * np.sum(np.angle(np.exp(1j * turn)) ** 2)
    return float(kinetic + gravity + springs + bending)


def _inputs(frame: int) -> SpringFrameInputs:
    return SpringFrameInputs(frame, (frame - 1) / FPS, 1.0 / FPS, gravity=(0.0, 0.0, -G))


def test_implicit_stiff_grid_at_one_step_per_frame_is_bounded_and_loses_energy():
    """Backward Euler dissipates: the total energy may never rise from one frame to the next.

    Allowance: the solve is inexact (CG stops at relative residual 1e-3, or at 200 iterations
    with what it has: on this grid up to ~6e-3, read from the solver each frame). A relative
    impulse error rho changes the energy exchanged in a frame (<= |Mg| |v| h ~ 0.8 J here) by
    at most rho times that; we allow rho * ENERGY_SCALE (10x more) plus 1e-6 ENERGY_SCALE.
    """
    model = _stiff_grid()
    solver = SpringMeshSolver(model, "IMPLICIT", 1, frame_dt=1 / FPS, frame=1)
    state = model.state()
    energy = [_energy(model, state)]
    allowance = []
    for frame in range(1, 101):
        solver.advance(state, _inputs(frame))
        energy.append(_energy(model, state))
        allowance.append((1e-6 + solver.integrator.last_residual) * ENERGY_SCALE)
        # bounded: stiff springs stay near their rest length (the weight alone stretches them by
        # ~1e-4; the linearised step overshoots to ~1.4% in the first frames), the sheet hangs
        length = np.linalg.norm(state.x[model.spring_i] - state.x[model.spring_j], axis=1)
        assert np.all(length < 1.05 * model.spring_rest)
        reach = np.linalg.norm(state.x[:, None, :] - model.rest_x[None, PINNED], axis=2).min(1)
        assert np.all(reach < 1.01 * np.hypot(SIZE, SIZE))
    assert state.x[:, 2].min() > -1.01 * SIZE  # it did fall (not stuck) and stays hanging
    assert energy[-1] < energy[0] - 0.3 * ENERGY_SCALE
    rise = np.diff(energy)
    bad = np.nonzero(rise > np.array(allowance))[0]
    assert len(bad) == 0, (
        f"energy rose in {len(bad)} frames, e.g. frame {bad[0] + 1}: +{rise[bad[0]]:.3g} J "
        f"(allowance {allowance[bad[0]]:.3g} J); rises {np.round(rise[bad], 4).tolist()}")


def _refusal(integrator: str) -> PhysanimError:
    with pytest.raises(PhysanimError) as info:
        SpringMeshSolver(_stiff_grid(), integrator, 1, frame_dt=1 / FPS, frame=7)
    return info.value


def test_explicit_euler_on_the_stiff_grid_is_refused_with_a_clear_message():
    error = _refusal("EULER")
    message = str(error)
    assert error.obj == "Sheet" and message.startswith('spring mesh "Sheet" at frame 7')
    assert "EULER" in message and "IMPLICIT" in message and "substeps" in message
    assert "100000 N/m" in message  # the value at fault


def test_symplectic_euler_with_the_substeps_the_message_asks_for_runs():
    """The refusal says how many substeps the explicit method needs; with that many it must run
    (here two frames: the grid starts hanging, the first frames are the most violent)."""
    message = str(_refusal("SYMPLECTIC_EULER"))
    substeps = int(re.search(r"about ([\d,]+) substeps", message).group(1).replace(",", ""))
    model = _stiff_grid()
    solver = SpringMeshSolver(model, "SYMPLECTIC_EULER", substeps, frame_dt=1 / FPS, frame=1)
    state = model.state()
    for frame in (1, 2):
        solver.advance(state, _inputs(frame))
    length = np.linalg.norm(state.x[model.spring_i] - state.x[model.spring_j], axis=1)
    assert np.all(length < 1.01 * model.spring_rest)
    assert state.x[:, 2].min() < -0.02  # it is falling (freely: g t^2 / 2 = 0.034 m)


@pytest.mark.parametrize("case", ["all pinned", "weightless at rest"])
def test_steps_with_nothing_to_solve_pass_quietly(case):
    """A mesh whose every vertex is pinned, or one at rest with no force on it (no gravity, no
    wind yet): the right-hand side is exactly zero; every step must pass (the state stays put)
    rather than be mistaken for a solve that lost positive definiteness."""
    x, edges, tris, ls, lt, lv = _grid(4, 4)
    pin = np.ones(16) if case == "all pinned" else None
    settings = SpringMeshSettings("Still", mass=1.0, stiffness=K, damping=1.0)
    model = SpringMeshBuilder(settings, x, edges, tris, ls, lt, lv, pin_weight=pin).finalize(1)
    solver = SpringMeshSolver(model, "IMPLICIT", 1, frame_dt=1 / FPS, frame=1)
    state = model.state()
    gravity = (0.0, 0.0, -G) if case == "all pinned" else (0.0, 0.0, 0.0)
    for frame in range(1, 5):
        solver.advance(state, SpringFrameInputs(frame, (frame - 1) / FPS, 1 / FPS,
                                                gravity=gravity))
    np.testing.assert_array_equal(state.x, model.rest_x)
    np.testing.assert_array_equal(state.v, 0.0)


DROP = 0.8  # [m]: the corner-down cloth's lowest corner above the ground
GROUND = ColliderFrame("Ground", "PLANE", np.diag([10.0, 10.0, 1.0, 1.0]),
                       np.diag([10.0, 10.0, 1.0, 1.0]))


def _standing_cloth(n: int = 16):
    """A 1 m square cloth at the defaults, standing on a corner in the XZ plane DROP above the
    ground: landing, its lowest rows stop on the ground's line and its triangles there are
    squashed flat in a sub-step."""
    x, edges, tris, ls, lt, lv = _grid(n, n, SIZE)
    u, w = (x[:, 0] - x[:, 1]) / math.sqrt(2.0), (x[:, 0] + x[:, 1]) / math.sqrt(2.0)
    x = np.stack([u, np.zeros(len(u)), w + DROP], axis=1)
    return SpringMeshBuilder(SpringMeshSettings("Cloth"), x, edges, tris, ls, lt, lv).finalize(1)


def _drop(solver, model, frames: int = 48) -> list[float]:
    """Kinetic + gravitational energy [J] (a lower bound of the total) after every frame."""
    state = model.state()
    out = []
    for frame in range(1, frames + 1):
        solver.advance(state, SpringFrameInputs(frame, (frame - 1) / FPS, 1 / FPS,
                                                gravity=(0.0, 0.0, -G), colliders=[GROUND]))
        assert np.all(np.isfinite(state.x)) and state.x[:, 2].min() > -1e-6, frame
        m = model.vertex_mass
        out.append(float(0.5 * np.sum(m * np.sum(state.v ** 2, axis=1))
                         + G * np.sum(m * state.x[:, 2])))
    return out


@pytest.mark.parametrize("substeps", [1, 2])
@pytest.mark.parametrize("integrator", ["IMPLICIT", "BDF2"])
def test_a_cloth_dropped_standing_on_its_corner_lands_without_gaining_energy(integrator,
                                                                             substeps):
    """Only the integrator and sub-steps chosen. Its bottom rows land on the ground's line,
    squashing triangles flat (their hinges have no angle: their bending fades out). It never
    has more kinetic and gravitational energy than it started with (1 %: the solve's
    tolerance). BDF2 at one step per frame blew up (its solve lost positive definiteness at
    frame 11), its bending pushing squashed triangles with forces of 1e14 N."""
    model = _standing_cloth()
    start = G * float(np.sum(model.vertex_mass * model.rest_x[:, 2]))
    energy = _drop(SpringMeshSolver(model, integrator, substeps, frame_dt=1 / FPS, frame=1),
                   model)
    assert max(energy) <= 1.01 * start, (max(energy), start)


def test_newton_corrections_never_raise_the_end_energy_of_a_step():
    """The landing of the standing cloth (defaults, one step per frame) gains energy in its
    first solve, so Newton iterations follow; a full correction would raise the step's end
    energy further in some of them (measured here, independently of the solver's line search):
    the search halves it until it lowers the energy, or keeps the step where it is."""
    record = []

    class Watched(BaraffWitkin):
        def _line_search(self, system, h, x0, v0, dv, delta, e_end):
            def end(d):
                return system.energy(x0 + h * (v0 + dv + d), v0 + dv + d)
            full = end(delta)
            taken, energy = super()._line_search(system, h, x0, v0, dv, delta, e_end)
            record.append((e_end, full, None if taken is None else end(taken)))
            return taken, energy

    model = _standing_cloth()
    solver = SpringMeshSolver(model, "IMPLICIT", 1, frame_dt=1 / FPS, frame=1)
    solver.integrator = Watched()
    _drop(solver, model)
    assert any(full >= before for before, full, _ in record), record
    assert all(taken is None or taken < before for before, _, taken in record), record
