"""Spring meshes against analytic colliders: a cloth falls onto the ground and onto a sphere.

Vertices are collided continuously (as particles) and placed SKIN = 1e-4 m outside a surface
after a hit, so no vertex may end below a surface; we allow 1e-6 m for rounding. The
colliders' corners, edges and spheres are kept off the faces (no face enters either). Collisions
with restitution 0 and friction only take energy: the total (kinetic + gravitational + spring)
may never exceed its start, up to the implicit solve's inexactness (relative residual <= 1e-2
even at the iteration cap: 1e-2 of the starting energy).
"""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.collision.distance import closest_on_triangles
from physanim.core.collision.shapes import box_mesh
from physanim.core.collision.tritri import triangles_overlap
from physanim.core.contact import ColliderFrame
from physanim.core.springs import (SpringFrameInputs, SpringMeshBuilder, SpringMeshSettings,
                                   SpringMeshSolver)
from physanim.tests.core.helpers import grid as _grid, implicit_step_times

DT = 1.0 / 24.0
G = 9.81


def _cloth(name: str, centre, size: float = 1.0, n: int = 9):
    x, edges, tris, ls, lt, lv = _grid(n, n, size)
    x += np.asarray(centre) - [size / 2, size / 2, 0.0]
    settings = SpringMeshSettings(name, mass=0.3, stiffness=2000.0, damping=2.0,
                                  shear_stiffness=500.0, bend_stiffness=0.01, drag=0.5)
    return SpringMeshBuilder(settings, x, edges, tris, ls, lt, lv).finalize(1)


def _scaled(radius: float, centre=(0.0, 0.0, 0.0)) -> np.ndarray:
    m = np.diag([radius, radius, radius, 1.0])
    m[:3, 3] = centre
    return m


def _energy(model, state) -> float:
    m = model.vertex_mass
    length = np.linalg.norm(state.x[model.spring_i] - state.x[model.spring_j], axis=1)
    return float(0.5 * np.sum(m * np.sum(state.v ** 2, axis=1)) + G * np.sum(m * state.x[:, 2])
                 + 0.5 * np.sum(model.spring_stiffness * (length - model.spring_rest) ** 2))


def _drop(model, collider, frames: int, substeps: int):
    solver = SpringMeshSolver(model, "IMPLICIT", substeps, frame_dt=DT, frame=1)
    state = model.state()
    hits = 0
    for frame in range(1, frames + 1):
        hits += solver.advance(state, SpringFrameInputs(frame, frame * DT, DT,
                                                        colliders=[collider]))
        yield state, hits


@pytest.mark.parametrize("substeps", [1, 4])
def test_cloth_falling_on_the_ground_rests_above_it(substeps):
    ground = ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4), restitution=0.0,
                           friction=0.5)
    model = _cloth("Sheet", (0.0, 0.0, 0.4))
    start = _energy(model, model.state())
    for state, hits in _drop(model, ground, 96, substeps):  # noqa: B007 (lands by frame 8, then rests; last hits checked below)
        assert state.x[:, 2].min() >= -1e-6
        assert _energy(model, state) <= start * (1.0 + 1e-2)
    assert hits > 0
    # at rest on the ground, flat: every vertex within 1 cm of it, slower than 1/20 of what
    # gravity gives in one frame (g / 24 = 0.41 m/s: 0.02 m/s), and not drifting sideways —
    # the drop is symmetric, so any net horizontal motion of the centroid is spurious (1 mm)
    speed = np.linalg.norm(state.v, axis=1).max()
    drift = np.linalg.norm(state.x[:, :2].mean(axis=0) - model.rest_x[:, :2].mean(axis=0))
    assert state.x[:, 2].max() < 0.01
    assert speed < 0.02 and drift < 1e-3, f"resting cloth moves at {speed:.3g} m/s, drifted " \
                                          f"{drift:.3g} m sideways"


@pytest.mark.parametrize("substeps", [1, 2, 4])
def test_cloth_draped_over_a_sphere_never_enters_it(substeps):
    """The 'cloth drape' sample's setting (2 substeps), a finer and a coarser one. Vertices that
    hit the curved surface during a step are re-solved as constraints landing on it, so the
    stiff cloth around them slows with them instead of being stretched by a projection after
    the step: no energy is gained even at one step per frame."""
    radius, centre = 0.3, np.array([0.0, 0.0, 0.0])
    ball = ColliderFrame("Ball", "SPHERE", _scaled(radius, centre), _scaled(radius, centre),
                         restitution=0.0, friction=0.3)
    model = _cloth("Drape", (0.02, -0.01, 0.5))  # slightly off-centre
    start = _energy(model, model.state())
    for state, hits in _drop(model, ball, 36, substeps):  # noqa: B007 (last hits checked below)
        distance = np.linalg.norm(state.x - centre, axis=1)
        assert distance.min() >= radius - 1e-6
        energy = _energy(model, state)
        assert energy <= start * (1.0 + 1e-2), f"energy {energy:.4g} J > start {start:.4g} J"
    assert hits > 0
    top = np.argmin(np.linalg.norm(model.rest_x[:, :2] - [0.02, -0.01], axis=1))
    assert np.linalg.norm(state.x[top] - centre) < radius + 0.02  # it lies on the sphere
    assert state.x[:, 2].min() < -0.1  # and hangs around it


@pytest.mark.parametrize("shape", ["SPHERE", "BOX"])
@pytest.mark.parametrize("stiffness", [2000.0, 1e5])
@pytest.mark.parametrize("friction", [0.0, 1.0])
@pytest.mark.parametrize("offset", [(0.1, 0.05), (0.23, -0.17)])
def test_cloth_landing_off_centre_gains_no_energy(shape, stiffness, friction, offset):
    """A cloth dropped off-centre onto a sphere or a box slides off and drapes; stiff (k =
    1e5 N/m on 3.7 g vertices) or not, with or without friction, at two steps per frame the
    total energy never rises above its start (1e-2 allowance for the inexact solve) and
    neither a vertex nor a face enters the collider. (Before landing constraints, projected
    hits stretched the springs: the energy rose by up to 4.5x.) One exception, measured: the
    stiff cloth's 12.5 cm faces must clear a sphere curved more than they are (a face whose
    corners lie on it dips 6.5 mm inside), so on the frame it lands, lifting the faces that
    the landing solve left inside stretches its stiff springs: up to 7 % of the start for
    that frame, 10 % allowed."""
    size = 0.3
    collider = ColliderFrame("C", shape, _scaled(size), _scaled(size), restitution=0.0,
                             friction=friction)
    x, edges, tris, ls, lt, lv = _grid(9, 9, 1.0)
    x += np.asarray((*offset, 0.5)) - [0.5, 0.5, 0.0]
    settings = SpringMeshSettings("Landing", mass=0.3, stiffness=stiffness, damping=2.0,
                                  shear_stiffness=stiffness / 4, bend_stiffness=0.01, drag=0.5)
    model = SpringMeshBuilder(settings, x, edges, tris, ls, lt, lv).finalize(1)
    start = _energy(model, model.state())
    allowance = 0.1 if shape == "SPHERE" and stiffness > 1e4 else 1e-2
    for state, hits in _drop(model, collider, 36, 2):  # noqa: B007 (last hits checked below)
        assert _energy(model, state) <= start * (1.0 + allowance)
        corners = state.x[model.triangles]
        if shape == "SPHERE":
            assert np.linalg.norm(state.x, axis=1).min() >= size - 1e-6
            nearest = closest_on_triangles(np.zeros((len(corners), 3)), corners)[1]
            assert np.sqrt(nearest.min()) >= size - 1e-6
        else:
            assert (size - np.abs(state.x).max(axis=1)).max() <= 1e-6
            box = box_mesh(size)
            a, b = np.meshgrid(np.arange(len(corners)), np.arange(len(box.triangles)),
                               indexing="ij")
            assert not triangles_overlap(corners[a.ravel()],
                                         box.triangle_vertices[b.ravel()]).any()
    assert hits > 0


@pytest.mark.parametrize("speed, solves", [(0.03, 1), (0.5, 2)])
def test_a_sub_step_whose_vertices_only_dip_under_the_ground_is_solved_once(monkeypatch, speed,
                                                                            solves):
    """A sheet lying on the ground (SKIN above it), its forces lifting it (gravity up, 1
    m/s^2: no vertex is pressed in at the step's start), moving down into it: at 3 cm/s each
    vertex dips 0.4 mm under it in the sub-step, which the response puts right (a touch: less
    than LAND_LIFT, slower than the rest speed) — the sub-step is solved once, as the features'
    small lifts are; each such dip of a resting cloth cost a second solve (90 of the 125
    re-solves of the self-collision bench). At 0.5 m/s (1 cm under) the vertices land: it is
    solved again with them as landing constraints. Either way every vertex ends above the
    ground, not approaching it."""
    calls = implicit_step_times(monkeypatch)
    ground = ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4))
    model = _cloth("Lying", (0.0, 0.0, 1e-4))
    state = model.state()
    state.v[:, 2] = -speed
    solver = SpringMeshSolver(model, "IMPLICIT", 2, frame_dt=DT, frame=1)
    solver.advance(state, SpringFrameInputs(1, DT, DT, gravity=(0.0, 0.0, 1.0),
                                            colliders=[ground]))
    first = np.round(calls, 12) == np.round(DT, 12)
    assert first.sum() == solves, calls
    assert state.x[:, 2].min() >= -1e-6 and state.v[:, 2].min() >= -1e-9


def test_touches_are_small_slow_hits_on_flat_colliders():
    """What counts as a touch (not solved again): moved less than LAND_LIFT by the response,
    slower than the rest speed, on a collider marked flat (the solver marks half-spaces and
    planes that are not bodies stepped first: see landing.touches for why not curved ones)."""
    from physanim.core.contact import Contacts
    from physanim.core.springs import landing

    k = 4
    up = np.tile([0.0, 0.0, 1.0], (k, 1))
    hit = Contacts.of(np.arange(k), np.zeros((k, 3)), up, np.zeros((k, 3)), np.zeros(k),
                      np.zeros(k), impulse=np.array([0.01, 0.01, 0.5, 0.01]),
                      collider=np.array([0, 0, 0, 1]))
    solved = np.zeros((k, 3))
    placed = solved + up * np.array([[0.9 * landing.LAND_LIFT], [1.1 * landing.LAND_LIFT],
                                     [1e-4], [1e-4]])
    assert landing.touches(hit, solved, placed, 0.41, np.array([True, False])).tolist() == \
        [True, False, False, False]
    assert not landing.touches(hit, solved, placed, 0.41, np.zeros(0, bool)).any()
    # a landing with any vertex that is not a touch lands every new one; all touches: none
    base = Contacts.none()
    x0 = np.zeros((k, 3))
    free = np.ones(k, bool)
    touch = np.array([True, True, True, False])
    assert landing.contacts(base, hit, x0, 0.02, free, touch=touch).index.tolist() == [0, 1, 2, 3]
    assert landing.contacts(base, hit, x0, 0.02, free, touch=np.ones(k, bool)) is None
