"""The uniform grid over a mesh's triangles (core/collision/cells.py) answers segment and closest-
point queries exactly as the hierarchy alone does: same triangles, times, points and features,
on cell boundaries, with large and zero-area triangles, and for long queries it hands back to
the tree. Particles raining on a mesh collider bake to the same bits with and without it."""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.collision import TriangleMesh, build_bvh, closest_points, segment_hits
from physanim.core.collision.cells import MAX_ENTRIES, QUERY_CELLS, TriangleCells
from physanim.core.collision.shapes import grid_mesh, sphere_mesh

from .test_collision_proximity import _brute_first_hits


def _bumpy():
    mesh = sphere_mesh(3)
    rng = np.random.default_rng(0)
    return TriangleMesh(mesh.vertices * rng.uniform(0.9, 1.1, (mesh.vertex_count, 1)),
                        mesh.triangles, "bumpy")


def _near_surface(mesh, n, rng, jitter):
    """Points on random triangles of ``mesh`` moved by ``jitter`` (normal, per axis)."""
    tri = mesh.triangle_vertices
    w = rng.dirichlet([1, 1, 1], n)
    p = np.einsum("nk,nkj->nj", w, tri[rng.integers(0, len(tri), n)])
    return p + rng.normal(0.0, jitter, (n, 3))


def _same_hits(a, b):
    for name in ("hit", "t", "point", "normal", "front", "triangle"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def _same_closest(a, b):
    for name in ("distance", "signed_distance", "point", "normal", "triangle", "feature"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


@pytest.mark.parametrize("kind", ["aabb", "obb"])
def test_grid_answers_equal_the_tree_and_brute_force(kind):
    mesh = _bumpy()
    bvh = build_bvh(mesh, kind)
    cells = TriangleCells(bvh)
    assert cells.usable
    rng = np.random.default_rng(1)
    n = 20_000
    p0 = _near_surface(mesh, n, rng, 0.01)
    # mostly short segments (the grid's), some long ones (the tree's), some of zero length
    length = np.where(rng.random(n) < 0.8, 0.02, 1.0)[:, None]
    p1 = p0 + rng.normal(size=(n, 3)) * length
    p1[::10] = p0[::10]
    tree, grid = segment_hits(bvh, p0, p1), segment_hits(bvh, p0, p1, cells=cells)
    _same_hits(tree, grid)
    want_t, want_tri = _brute_first_hits(mesh, p0, p1)
    np.testing.assert_array_equal(grid.triangle, want_tri)
    np.testing.assert_array_equal(grid.t, want_t)
    assert 0.2 < grid.hit.mean() < 0.8
    assert not grid.hit[::10].any()  # a point never crosses a surface
    assert grid.n_v < 0.5 * tree.n_v  # most answered by one lookup, not a descent
    for reach in (1e-3, 0.02, 0.3):
        tree_cp = closest_points(bvh, p0, max_distance=reach)
        grid_cp = closest_points(bvh, p0, max_distance=reach, cells=cells)
        _same_closest(tree_cp, grid_cp)
        assert 0.0 < (grid_cp.triangle >= 0).mean()
    assert (grid_cp.triangle >= 0).all()


@pytest.mark.parametrize("grid", [False, True])
def test_each_point_its_own_reach_answers_as_asked_alone(grid):
    """closest_points with a reach per point: each point's answer is the one it gets asked
    with its reach alone (found within it, or not at all), through the tree and the grid."""
    mesh = _bumpy()
    bvh = build_bvh(mesh, "aabb")
    cells = TriangleCells(bvh) if grid else None
    rng = np.random.default_rng(4)
    p = _near_surface(mesh, 3000, rng, 0.05)
    reach = rng.choice([1e-3, 0.01, 0.05, 0.3], len(p))
    got = closest_points(bvh, p, max_distance=reach, cells=cells)
    for r in np.unique(reach):
        rows = np.nonzero(reach == r)[0]
        alone = closest_points(bvh, p[rows], max_distance=float(r), cells=cells)
        for name in ("distance", "point", "triangle", "feature"):
            np.testing.assert_array_equal(getattr(got, name)[rows], getattr(alone, name),
                                          err_msg=name)
    found = got.triangle >= 0
    assert 0.1 < found.mean() < 0.95 and (got.distance[found] <= reach[found]).all()


def test_grid_on_cell_boundaries_with_large_and_zero_area_triangles():
    # a detailed grid beside one huge ground quad (too many cells: tested by every query), and
    # zero-area triangles (never hit, but their edges are closest points)
    detail = grid_mesh(40, size=1.0, amplitude=0.05)
    v = np.asarray(detail.vertices)
    t = np.asarray(detail.triangles)
    ground_v = np.array([[-20.0, -20, -0.2], [20, -20, -0.2], [20, 20, -0.2], [-20, 20, -0.2]])
    flat_v = np.array([[0.3, 0.3, 0.1], [0.5, 0.5, 0.1], [0.7, 0.7, 0.1]])
    verts = np.concatenate([v, ground_v, flat_v])
    k = len(v)
    tris = np.concatenate([t, [[k, k + 1, k + 2], [k, k + 2, k + 3]], [[k + 4, k + 5, k + 6]]])
    mesh = TriangleMesh(verts, tris, "mixed")
    bvh = build_bvh(mesh, "aabb")
    cells = TriangleCells(bvh)
    assert cells.usable and len(cells.large) == 3  # the two ground halves, the zero-area one
    rng = np.random.default_rng(2)
    n = 6000
    # points exactly on cell faces, edges and corners, and random ones near the surfaces
    grid_pts = cells.origin + cells.cell_size * rng.integers(0, 60, (n // 2, 3))
    p = np.concatenate([grid_pts, _near_surface(mesh, n // 2, rng, 0.02)])
    p[:, 2] = np.where(rng.random(n) < 0.3, -0.2, p[:, 2])  # some on the ground plane
    along = np.zeros((n, 3))
    along[np.arange(n), rng.integers(0, 3, n)] = cells.cell_size  # along a cell edge
    q = p + np.where(rng.random(n)[:, None] < 0.5, along, rng.normal(0, 0.01, (n, 3)))
    _same_hits(segment_hits(bvh, p, q), segment_hits(bvh, p, q, cells=cells))
    for reach in (1e-3, cells.cell_size):
        _same_closest(closest_points(bvh, p, max_distance=reach),
                      closest_points(bvh, p, max_distance=reach, cells=cells))
    # the zero-area triangle is the closest feature for points beside its segment
    flat = closest_points(bvh, np.array([[0.5, 0.5, 0.12]]), max_distance=0.05, cells=cells)
    assert flat.triangle[0] == len(tris) - 1
    np.testing.assert_allclose(flat.distance, 0.02)


def test_long_queries_go_to_the_tree_and_unsuitable_meshes_get_no_grid():
    mesh = _bumpy()
    bvh = build_bvh(mesh, "aabb")
    cells = TriangleCells(bvh)
    size = cells.cell_size
    side = 0.5 * (QUERY_CELLS + 1) * size  # a square over more cells than a query may use
    lo = np.array([[0.0, 0.0, 0.0], [-side, -side, 0.0]])
    hi = np.array([[0.5 * size] * 3, [side, side, 0.0]])
    query, pos, rest = cells.candidates(lo, hi)
    np.testing.assert_array_equal(rest, [1])
    assert set(query) <= {0}
    # long thin shards across one another: cells grow until the lists stay small; the
    # answers do not change
    rng = np.random.default_rng(3)
    shards = TriangleMesh(rng.normal(size=(600, 3)) * 10.0, np.arange(600).reshape(-1, 3), "s")
    sbvh = build_bvh(shards, "aabb")
    grown = TriangleCells(sbvh)
    assert grown.usable and len(grown.entries) <= MAX_ENTRIES * 200
    p0 = rng.normal(size=(3000, 3)) * 5.0
    p1 = p0 + rng.normal(size=(3000, 3)) * 0.3
    _same_hits(segment_hits(sbvh, p0, p1), segment_hits(sbvh, p0, p1, cells=grown))
    _same_closest(closest_points(sbvh, p0, max_distance=0.5),
                  closest_points(sbvh, p0, max_distance=0.5, cells=grown))
    # a mesh of one point has no cell size: no grid, and queries given it use the tree
    point = TriangleMesh(np.zeros((3, 3)), [[0, 1, 2]], "point")
    pbvh = build_bvh(point, "aabb")
    none = TriangleCells(pbvh)
    assert not none.usable
    got = closest_points(pbvh, [[0.0, 0.0, 1e-3]], max_distance=0.01, cells=none)
    np.testing.assert_allclose(got.distance, 1e-3)


def test_particles_on_a_mesh_collider_bake_the_same_with_and_without_the_grid(monkeypatch):
    from physanim.core import contact
    from physanim.core import particles as P
    from physanim.core.contact.mesh import MeshHierarchies

    mesh = grid_mesh(40, size=4.0, amplitude=0.2)
    verts = np.asarray(mesh.vertices) - [2.0, 2.0, 0.0]

    def bake():
        builder = P.ParticleModelBuilder(seed=1)
        builder.add_emitter(P.EmitterSettings("Rain"))
        model = builder.finalize()
        state = model.state()
        rng = np.random.default_rng(4)
        n = 3000
        x = np.column_stack([rng.uniform(-1.8, 1.8, (n, 2)), rng.uniform(0.3, 1.5, n)])
        state.append(0, x, rng.normal(0, 0.5, (n, 3)), np.ones(n), np.zeros(n),
                     np.full(n, 1e9), np.full(n, 0.02))
        ground = contact.ColliderFrame("Ground", "MESH", np.eye(4), np.eye(4), restitution=0.3,
                                       friction=0.4, vertices0=verts, vertices1=verts,
                                       triangles=np.asarray(mesh.triangles))
        solver = P.ParticleSolver(model, "SYMPLECTIC_EULER", 2)
        for f in range(30):
            solver.advance(state, P.FrameInputs(f, f / 24, 1 / 24,
                                                emitters=[P.EmitterFrame(active=False)],
                                                colliders=[ground]))
        return state.particle_x.copy(), state.particle_v.copy()

    used = []
    real = MeshHierarchies.cells
    monkeypatch.setattr(MeshHierarchies, "cells",
                        lambda self, name, bvh: used.append(name) or real(self, name, bvh))
    x_grid, v_grid = bake()
    assert used
    monkeypatch.setattr(MeshHierarchies, "cells", lambda self, name, bvh: None)
    x_tree, v_tree = bake()
    np.testing.assert_array_equal(x_grid, x_tree)
    np.testing.assert_array_equal(v_grid, v_tree)
    # most of the rain landed and rests on the mesh (the run exercised the resting queries;
    # some rolled off its edges)
    assert (np.linalg.norm(v_grid, axis=1) < 1e-3).mean() > 0.5


def test_a_cloth_on_a_mesh_collider_bakes_the_same_with_and_without_the_grid(monkeypatch):
    from physanim.core.contact import ColliderFrame
    from physanim.core.contact.mesh import MeshHierarchies
    from physanim.core.springs import (SpringFrameInputs, SpringMeshBuilder, SpringMeshSettings,
                                       SpringMeshSolver)

    ball = sphere_mesh(3)
    verts, tris = np.asarray(ball.vertices) * 0.4, np.asarray(ball.triangles)
    grid = grid_mesh(13, 1.0)
    t = np.asarray(grid.triangles)
    x = np.asarray(grid.vertices) + [-0.5, -0.5, 0.6]
    edges = np.unique(np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]),
                              axis=1), axis=0)
    settings = SpringMeshSettings("Sheet", mass=0.3, stiffness=2000.0, damping=2.0,
                                  shear_stiffness=500.0, bend_stiffness=0.01, drag=0.5)
    dt = 1 / 24

    def bake():
        model = SpringMeshBuilder(settings, x, edges, t, 3 * np.arange(len(t)),
                                  np.full(len(t), 3), t.ravel()).finalize(1)
        ball_frame = ColliderFrame("Ball", "MESH", np.eye(4), np.eye(4), restitution=0.0,
                                   friction=0.5, vertices0=verts, vertices1=verts, triangles=tris)
        solver = SpringMeshSolver(model, "IMPLICIT", 2, frame_dt=dt, frame=1)
        state = model.state()
        for frame in range(1, 31):
            solver.advance(state, SpringFrameInputs(frame, frame * dt, dt, colliders=[ball_frame]))
        return state.x.copy()

    with_grid = bake()
    monkeypatch.setattr(MeshHierarchies, "cells", lambda self, name, bvh: None)
    np.testing.assert_array_equal(with_grid, bake())
    assert with_grid[:, 2].max() > 0.38  # draped over the ball, not through it
