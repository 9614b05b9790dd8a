"""Force objects on spring meshes: drag, attractors and vortices act on the whole mesh as on one
particle of its total mass (shared by vertex mass), so a mesh's motion under them follows the
closed form of a single particle and does not depend on how finely the mesh is subdivided."""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.forces import Attractor, Drag, Vortex
from physanim.core.springs import (SpringFrameInputs, SpringMeshBuilder, SpringMeshSettings,
                                   SpringMeshSolver)
from physanim.tests.core.helpers import grid as _grid

FPS = 24
MASS = 2.0


def _mesh(n: int, offset=(0.0, 0.0, 0.0), mass_mode: str = "EVEN"):
    x, edges, tris, ls, lt, lv = _grid(n, n, 0.2)
    settings = SpringMeshSettings("Sheet", mass=MASS, mass_mode=mass_mode, stiffness=5e3,
                                  shear_stiffness=2e3, drag=0.0)
    return SpringMeshBuilder(settings, x + offset, edges, tris, ls, lt, lv).finalize(1)


def _run(model, fields, frames: int, v0=(0.0, 0.0, 0.0), integrator="IMPLICIT", substeps=2):
    solver = SpringMeshSolver(model, integrator, substeps, frame_dt=1.0 / FPS)
    state = model.state()
    state.v[:] = v0
    for f in range(frames):
        solver.advance(state, SpringFrameInputs(frame=f, t0=f / FPS, frame_dt=1.0 / FPS,
                                                gravity=(0.0, 0.0, 0.0), fields=fields))
    return state


@pytest.mark.parametrize("integrator, substeps", [("IMPLICIT", 2), ("SYMPLECTIC_EULER", 30)])
def test_drag_slows_the_mesh_like_one_particle_of_its_mass(integrator, substeps):
    k = 0.8  # [kg/s]
    v0 = np.array([3.0, -1.0, 2.0])
    frames = 24
    state = _run(_mesh(6), [Drag("Air", k)], frames, v0, integrator, substeps)
    h = 1.0 / FPS / substeps
    # uniform translation stretches no spring: each step is v <- v (1 - h k / M) exactly
    expected = v0 * (1.0 - h * k / MASS) ** (frames * substeps)
    np.testing.assert_allclose(state.v, np.broadcast_to(expected, state.v.shape), rtol=1e-9)


@pytest.mark.parametrize("mass_mode", ["EVEN", "AREA"])
def test_attractor_pulls_the_mesh_as_one_particle_whatever_its_resolution(mass_mode):
    strength, frames = 1.5, 24  # [N], falloff 0: a constant pull towards the centre
    pull = [Attractor("Pull", (50.0, 0.0, 0.0), strength, falloff=0.0)]
    moved = []
    for n in (4, 9):
        model = _mesh(n, offset=(-0.1, -0.1, 0.0), mass_mode=mass_mode)  # centred on the line
        start = model.rest_x.mean(axis=0)
        state = _run(model, pull, frames)
        moved.append(state.x.mean(axis=0) - start)
    # 50 m away, every vertex is pulled along +x (cosines within 1e-5 of 1): the centre of mass
    # moves as a particle of mass M under a constant force, stepped by (semi-)implicit Euler
    h, steps = 1.0 / FPS / 2, frames * 2
    expected_x = strength / MASS * h * h * steps * (steps + 1) / 2
    for d in moved:
        assert d[0] == pytest.approx(expected_x, rel=1e-4)
        assert abs(d[1]) < 1e-4 * expected_x and abs(d[2]) < 1e-4 * expected_x
    np.testing.assert_allclose(moved[0], moved[1], rtol=1e-4, atol=1e-6)


def test_vortex_turns_the_mesh_about_its_axis():
    model = _mesh(5, offset=(3.0, -0.1, -0.1))  # a small sheet on the +x side of the z axis
    state = _run(model, [Vortex("Swirl", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 2.0)], 12)
    c = state.x.mean(axis=0)
    c0 = model.rest_x.mean(axis=0)
    # the push is along z x r = +y at the sheet: it moves along +y, stays in its plane
    assert c[1] - c0[1] > 0.05
    assert abs(c[2] - c0[2]) < 1e-6
