"""Spring-mesh model: topology (hinges, diagonals, distance-2 pairs, areas, volume), mass
distribution, spring families, and bad input (loose vertices, zero-length edges, meshes without
faces, bad mass, non-finite rest positions)."""
from __future__ import annotations

import itertools

import numpy as np
import pytest

from physanim.core.errors import PhysanimError
from physanim.core.forces import ParticleView
from physanim.core.springs import (SpringFrameInputs, SpringMeshBuilder, SpringMeshSettings,
                                   SpringMeshSolver, topology)
from physanim.tests.core.helpers import grid as _grid

G = 9.81
DT = 1.0 / 24.0


def _cube():
    """Unit cube [0, 1]^3 as 12 outward-facing triangles."""
    x = np.array(list(itertools.product([0.0, 1.0], repeat=3)))  # index = 4 i + 2 j + k
    quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    tris = np.array([t for q in quads for t in ([q[0], q[1], q[2]], [q[0], q[2], q[3]])])
    return x, tris


# -- topology -----------------------------------------------------------------------------------

@pytest.mark.parametrize("nx,ny", [(2, 2), (4, 3), (6, 7)])
def test_hinges_of_a_grid_are_its_interior_edges_with_their_wings(nx, ny):
    x, _, tris, *_ = _grid(nx, ny)
    hinge = topology.hinges(tris)
    # edges: (nx-1) ny horizontal + nx (ny-1) vertical + one diagonal per quad; the boundary
    # has 2 (nx-1) + 2 (ny-1) of them; every other edge is shared by exactly two triangles
    interior = (nx - 1) * ny + nx * (ny - 1) + (nx - 1) * (ny - 1) - 2 * (nx - 1) - 2 * (ny - 1)
    assert hinge.shape == (interior, 4)
    oriented = {tuple(np.roll(t, r)) for t in tris.tolist() for r in range(3)}
    edges = set()
    for e0, e1, w0, w1 in hinge.tolist():
        assert (e0, e1, w0) in oriented and (e1, e0, w1) in oriented  # the two wings, oriented
        assert w0 != w1 and len({e0, e1, w0, w1}) == 4
        edges.add(frozenset((e0, e1)))
    assert len(edges) == interior
    np.testing.assert_allclose(topology.dihedral_angles(x, hinge), 0.0, atol=1e-15)  # flat


def test_hinges_skip_boundary_and_non_manifold_edges():
    # three triangles on edge 0-1 (a fin): not a hinge; every other edge is a boundary edge
    fin = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    assert topology.hinges(fin).shape == (0, 4)
    np.testing.assert_array_equal(topology.hinges(fin[:2]), [[0, 1, 2, 3]])
    assert topology.hinges(np.zeros((0, 3))).shape == (0, 4)


def test_polygon_diagonals_of_quads_and_ngons():
    x, _, _, ls, lt, lv = _grid(5, 4)
    quads = topology.polygon_diagonals(ls, lt, lv)
    assert quads.shape == (2 * 4 * 3, 2)  # two per quad, none shared
    assert np.all(quads[:, 0] < quads[:, 1])
    length = np.linalg.norm(x[quads[:, 0]] - x[quads[:, 1]], axis=1)
    np.testing.assert_allclose(length, np.hypot(0.25, 1.0 / 3.0))  # all are quad diagonals
    for n in range(3, 9):  # one n-gon: n (n - 3) / 2 diagonals
        d = topology.polygon_diagonals([0], [n], np.arange(n))
        assert len(d) == n * (n - 3) // 2
        gap = (d[:, 1] - d[:, 0]) % n
        assert np.all((gap >= 2) & (gap <= n - 2))  # never a side
    # mixed sizes in one call: a triangle, a pentagon and a hexagon (offsets into the loops)
    d = topology.polygon_diagonals([0, 3, 8], [3, 5, 6], np.arange(14))
    assert len(d) == 0 + 5 + 9


def test_distance2_pairs_join_the_wings_of_each_hinge():
    tris = np.array([[0, 1, 2], [1, 0, 3]])
    hinge = topology.hinges(tris)
    np.testing.assert_array_equal(topology.distance2_pairs(hinge), [[2, 3]])
    _, _, grid_tris, *_ = _grid(5, 5)
    hinge = topology.hinges(grid_tris)
    pairs = topology.distance2_pairs(hinge)
    expected = {tuple(sorted(h[2:])) for h in hinge.tolist()}
    assert {tuple(p) for p in pairs.tolist()} == expected and len(pairs) == len(expected)
    # duplicated hinges give each pair once
    assert len(topology.distance2_pairs(np.concatenate([hinge, hinge]))) == len(expected)
    assert topology.distance2_pairs(np.zeros((0, 4), np.int64)).shape == (0, 2)


def test_vertex_areas_sum_to_the_surface_area():
    rng = np.random.default_rng(3)
    x, _, tris, *_ = _grid(6, 5, 2.0)
    x[:, 2] = rng.normal(scale=0.2, size=len(x))
    cross = np.cross(x[tris[:, 1]] - x[tris[:, 0]], x[tris[:, 2]] - x[tris[:, 0]])
    total = 0.5 * np.linalg.norm(cross, axis=1).sum()
    area = topology.vertex_areas(x, tris)
    assert area.sum() == pytest.approx(total, rel=1e-12)
    flat = topology.vertex_areas(_grid(3, 3, 2.0)[0], _grid(3, 3, 2.0)[2])
    # corners: 1 or 2 of the eight 0.5 m^2 triangles, each a third; centre: 6 of them
    np.testing.assert_allclose(flat[[0, 2, 6, 8]], [1 / 3, 1 / 6, 1 / 6, 1 / 3])
    assert flat[4] == pytest.approx(1.0)


def test_signed_volume_of_a_unit_cube():
    x, tris = _cube()
    assert topology.signed_volume(x, tris) == pytest.approx(1.0, rel=1e-14)
    assert topology.signed_volume(x + [3.0, -7.0, 2.0], tris) == pytest.approx(1.0, rel=1e-12)
    assert topology.signed_volume(x, tris[:, ::-1]) == pytest.approx(-1.0, rel=1e-14)
    assert topology.signed_volume(2.0 * x, tris) == pytest.approx(8.0, rel=1e-14)
    assert len(topology.hinges(tris)) == 18  # closed: every edge is a hinge


# -- mass ---------------------------------------------------------------------------------------

def _settings(name="Mesh", **kw):
    return SpringMeshSettings(name, **kw)


def test_even_mass_gives_every_vertex_mass_over_n():
    x, e, t, *_ = _grid(4, 3)
    model = SpringMeshBuilder(_settings(mass=2.4), x, e, t).finalize()
    np.testing.assert_array_equal(model.vertex_mass, np.full(12, 2.4 / 12))
    assert model.vertex_mass.sum() == pytest.approx(2.4, rel=1e-15)


def test_area_mass_is_proportional_to_vertex_area_and_loose_vertices_get_the_mean():
    """Triangles (0,1,2) of 0.5 m^2 and (1,3,2) of 1.5 m^2, vertex 4 loose; 5 kg. The loose vertex
    gets the mean 5/5 = 1 kg; the other 4 kg go by vertex area (a third of each triangle):
    areas 1/6, 2/3, 2/3, 1/2 of 2 m^2 -> 1/3, 4/3, 4/3, 1 kg."""
    x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 2, 0], [5, 5, 5]], float)
    tris = [[0, 1, 2], [1, 3, 2]]
    edges = [[0, 1], [1, 2], [2, 0], [1, 3], [3, 2]]
    model = SpringMeshBuilder(_settings(mass=5.0, mass_mode="AREA"), x, edges, tris).finalize()
    np.testing.assert_allclose(model.vertex_mass, [1 / 3, 4 / 3, 4 / 3, 1.0, 1.0], rtol=1e-14)
    assert model.vertex_mass.sum() == pytest.approx(5.0, rel=1e-15)


def test_area_mass_total_is_exact_on_a_random_mesh():
    rng = np.random.default_rng(8)
    x, e, t, *_ = _grid(7, 6)
    x += rng.normal(scale=0.03, size=x.shape)
    x = np.vstack([x, [[9.0, 9.0, 9.0], [8.0, 8.0, 8.0]]])  # two loose vertices
    model = SpringMeshBuilder(_settings(mass=3.7, mass_mode="AREA"), x, e, t).finalize()
    assert model.vertex_mass.sum() == pytest.approx(3.7, rel=1e-14)
    assert np.all(model.vertex_mass > 0)
    np.testing.assert_allclose(model.vertex_mass[-2:], 3.7 / len(x))
    area = topology.vertex_areas(x, t)[:-2]
    np.testing.assert_allclose(model.vertex_mass[:-2] / area,
                               (3.7 - 2 * 3.7 / len(x)) / area.sum(), rtol=1e-12)


def test_area_mass_without_faces_is_an_error_suggesting_even():
    with pytest.raises(PhysanimError, match=r'spring mesh "Rope" at frame 5: .*use EVEN'):
        SpringMeshBuilder(_settings("Rope", mass_mode="AREA"), [[0, 0, 0], [1, 0, 0]],
                          [[0, 1]], np.zeros((0, 3))).finalize(5)


@pytest.mark.parametrize("mass", [-1.0, 0.0, float("nan"), float("inf")])
def test_non_positive_or_non_finite_mass_is_a_value_error_naming_it(mass):
    message = rf'spring mesh "Blob": mass must be > 0 kg \(got {mass}\)'
    with pytest.raises(ValueError, match=message):
        _settings("Blob", mass=mass)


@pytest.mark.parametrize("key", ["stiffness", "damping", "shear_stiffness", "bend_stiffness",
                                 "drag", "pin_stiffness"])
def test_negative_constants_are_value_errors_naming_them(key):
    with pytest.raises(ValueError, match=rf'"Blob": {key} must be finite and >= 0 \(got -2.0\)'):
        _settings("Blob", **{key: -2.0})


def test_unknown_modes_are_value_errors():
    with pytest.raises(ValueError, match="mass_mode must be one of"):
        _settings(mass_mode="VOLUME")
    with pytest.raises(ValueError, match="bend_mode must be one of"):
        _settings(bend_mode="TWIST")


# -- spring families ----------------------------------------------------------------------------

def test_spring_families_of_a_quad_grid():
    nx, ny = 5, 4
    x, e, t, ls, lt, lv = _grid(nx, ny)
    unique_edges = (nx - 1) * ny + nx * (ny - 1)  # the quads list shared edges twice
    quads = (nx - 1) * (ny - 1)
    hinges = len(topology.hinges(t))
    angular = SpringMeshBuilder(_settings(), x, e, t, ls, lt, lv).finalize()
    assert np.count_nonzero(angular.spring_family == 0) == unique_edges
    assert np.count_nonzero(angular.spring_family == 1) == 2 * quads
    assert angular.hinge.shape == (hinges, 4)
    np.testing.assert_allclose(angular.hinge_rest, 0.0, atol=1e-15)
    rest = np.linalg.norm(x[angular.spring_i] - x[angular.spring_j], axis=1)
    np.testing.assert_array_equal(angular.spring_rest, rest)
    distance = SpringMeshBuilder(_settings(bend_mode="DISTANCE", bend_stiffness=7.0), x, e, t,
                                 ls, lt, lv).finalize()
    assert np.count_nonzero(distance.spring_family == 2) == hinges and len(distance.hinge) == 0
    np.testing.assert_array_equal(distance.spring_stiffness[distance.spring_family == 2], 7.0)
    bare = SpringMeshBuilder(_settings(shear_stiffness=0.0, bend_mode="NONE"), x, e, t, ls, lt,
                             lv).finalize()
    assert np.all(bare.spring_family == 0) and len(bare.hinge) == 0
    limp = SpringMeshBuilder(_settings(bend_stiffness=0.0, bend_damping=0.0), x, e, t).finalize()
    assert len(limp.hinge) == 0  # an angular family with no stiffness or damping is left out
    for a in (angular.rest_x, angular.vertex_mass, angular.spring_i, angular.hinge,
              angular.pinned):
        assert not a.flags.writeable


# -- bad input ----------------------------------------------------------------------------------

def test_loose_vertices_fall_freely():
    """A loose vertex (no springs) only feels gravity. RK4 integrates x = x0 - g t^2/2 exactly (a
    quadratic): 1e-12. Backward Euler: v_n = -g n h, x_n = x0 - g h^2 n (n + 1)/2 (O(h) behind
    the parabola), up to the solve's 1e-3 relative residual on the gravity impulse."""
    x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [3.0, 3.0, 2.0]])
    pin = [1.0, 1.0, 0.0, 0.0]
    settings = _settings("Bits", stiffness=50.0, drag=0.0)  # RK4: omega h = 20 / 24
    frames = 24
    n = np.arange(1, frames + 1)
    for integrator, expected, tol in (
            ("RK4", 2.0 - 0.5 * G * (n * DT) ** 2, 1e-12),
            ("IMPLICIT", 2.0 - 0.5 * G * DT ** 2 * n * (n + 1), 1e-3 * 0.5 * G * (n * DT) ** 2)):
        model = SpringMeshBuilder(settings, x, [[0, 1], [1, 2], [2, 0]], [[0, 1, 2]],
                                  pin_weight=pin).finalize()
        solver = SpringMeshSolver(model, integrator, 1, frame_dt=DT)
        state = model.state()
        z = []
        for frame in range(frames):
            solver.advance(state, SpringFrameInputs(frame, frame * DT, DT))
            z.append(state.x[3, 2])
        error = np.abs(np.array(z) - expected)
        assert np.all(error <= tol), (integrator, error.max())
        np.testing.assert_array_equal(state.x[3, :2], [3.0, 3.0])


def test_zero_length_edge_gives_finite_forces():
    """Duplicate vertices joined by an edge: a zero-rest-length spring, f = -k l (no direction
    needed). At zero length the force is exactly zero, not NaN."""
    x, e, t, *_ = _grid(3, 3)
    x2 = np.vstack([x, x[4]])
    model = SpringMeshBuilder(_settings("Seam"), x2, np.vstack([e, [[4, 9]]]), t).finalize()
    assert model.spring_rest.min() == 0.0
    springs = SpringMeshSolver(model, "IMPLICIT", 1, frame_dt=DT).springs
    x = model.rest_x
    out = np.zeros_like(x)
    springs.apply(ParticleView(x, np.ones_like(x), model.vertex_mass, 0.0), out)  # no warning
    np.testing.assert_array_equal(out, 0.0)
    jacobian = springs.linearize(ParticleView(x, np.ones_like(x), model.vertex_mass, 0.0))
    assert np.all(np.isfinite(jacobian.kx)) and np.all(np.isfinite(jacobian.kv))


def test_zero_length_edge_between_duplicate_vertices_simulates():
    """The same seam on a hanging sheet: the duplicate hangs from its twin on a zero-length
    spring, m g / k = 4e-4 m below it. That is not a torn spring: the bake must run and stay
    finite (the tear check must not divide by the zero rest length)."""
    x, e, t, ls, lt, lv = _grid(5, 5)
    x2 = np.vstack([x, x[12]])  # the centre, duplicated as vertex 25
    pin = np.zeros(26)
    pin[[20, 24]] = 1.0
    settings = _settings("Seam", mass=1.0, stiffness=1000.0)
    model = SpringMeshBuilder(settings, x2, np.vstack([e, [[12, 25]]]), t, ls, lt, lv,
                              pin_weight=pin).finalize(1)
    solver = SpringMeshSolver(model, "IMPLICIT", 1, frame_dt=DT, frame=1)
    state = model.state()
    for frame in range(1, 25):
        solver.advance(state, SpringFrameInputs(frame, frame * DT, DT))
    assert np.all(np.isfinite(state.x))
    sag = model.vertex_mass[25] * G / 1000.0
    assert np.linalg.norm(state.x[25] - state.x[12]) < 10 * sag


def test_mesh_without_faces_builds_edge_springs_only_and_simulates():
    """A rope: edges only. Shear and bending need faces, so there are none (the panel says so);
    the rope still hangs from its pinned end."""
    count = 8
    x = np.stack([np.linspace(0.0, 1.0, count), np.zeros(count), np.zeros(count)], axis=1)
    edges = np.stack([np.arange(count - 1), np.arange(1, count)], axis=1)
    pin = np.zeros(count)
    pin[0] = 1.0
    settings = _settings("Rope", shear_stiffness=100.0, bend_mode="ANGULAR")
    model = SpringMeshBuilder(settings, x, edges, np.zeros((0, 3)), pin_weight=pin).finalize()
    assert np.all(model.spring_family == 0) and len(model.spring_i) == count - 1
    assert len(model.hinge) == 0 and len(model.triangles) == 0
    for bend_mode in ("DISTANCE", "NONE"):
        other = SpringMeshBuilder(_settings("Rope", bend_mode=bend_mode), x, edges,
                                  np.zeros((0, 3))).finalize()
        assert np.all(other.spring_family == 0)
    solver = SpringMeshSolver(model, "IMPLICIT", 1, frame_dt=DT)
    state = model.state()
    for frame in range(24):
        solver.advance(state, SpringFrameInputs(frame, frame * DT, DT))
    assert np.all(np.isfinite(state.x)) and state.x[-1, 2] < -0.3
    np.testing.assert_array_equal(state.x[0], x[0])


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_non_finite_rest_position_is_an_error_naming_the_vertex(bad):
    x, e, t, *_ = _grid(3, 3)
    x[5, 1] = bad
    with pytest.raises(PhysanimError, match=r'spring mesh "Wreck" at frame 2: vertex 5 has a '
                                            r'non-finite rest position'):
        SpringMeshBuilder(_settings("Wreck"), x, e, t).finalize(2)


def test_other_bad_builder_input_is_named():
    x, e, t, *_ = _grid(3, 3)
    with pytest.raises(PhysanimError, match="has no vertices"):
        SpringMeshBuilder(_settings(), np.zeros((0, 3)), [], []).finalize()
    with pytest.raises(PhysanimError, match=r"edges refer to vertices outside 0\.\.8"):
        SpringMeshBuilder(_settings(), x, np.vstack([e, [[0, 9]]]), t).finalize()
    with pytest.raises(PhysanimError, match=r"triangles refer to vertices outside"):
        SpringMeshBuilder(_settings(), x, e, np.vstack([t, [[0, 1, -1]]])).finalize()
    with pytest.raises(PhysanimError, match=r"pin weights have shape \(4,\), expected \(9,\)"):
        SpringMeshBuilder(_settings(), x, e, t, pin_weight=np.ones(4)).finalize()
    model = SpringMeshBuilder(_settings(), x, e, t).finalize()
    with pytest.raises(ValueError, match=r"substeps must be an integer >= 1 \(got 0\)"):
        SpringMeshSolver(model, "IMPLICIT", 0)
