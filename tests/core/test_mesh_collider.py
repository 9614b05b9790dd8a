"""Any triangle mesh as a particle collider: no tunnelling through a thin single-sided mesh (fast
particles, a fast-rotating mesh, a deforming mesh), bounces and resting contact that match the
analytic half space, friction on a sloped mesh, and clear errors for bad input.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core.collision.shapes import grid_mesh
from physanim.core.contact import ColliderFrame
from physanim.core.particles import (
    EmitterFrame, EmitterSettings, FrameInputs, ParticleModelBuilder, ParticleSolver,
)
from physanim.core.contact import SKIN
from physanim.tests.core.helpers import (
    mesh_collider as _mesh_collider, place as _place, rotation as _rotation, sheet as _sheet,
    translation as _translate,
)

G = 9.81
DT = 1.0 / 24.0


def _model():
    builder = ParticleModelBuilder(0)
    builder.add_emitter(EmitterSettings("Shot"))
    return builder.finalize()


def _inputs(frame, colliders, gravity=(0.0, 0.0, -G)):
    return FrameInputs(frame=frame, t0=frame * DT, frame_dt=DT, gravity=gravity,
                       emitters=[EmitterFrame(active=False)], colliders=colliders)


# -- tunnelling ---------------------------------------------------------------------------------

# fast particles against a thin mesh: test_particles_collisions.py, shared with the analytic plane

def test_fast_rotating_mesh_sweeps_resting_particles_without_crossing():
    # A revolving door: a thin vertical sheet (local xz plane, |x| <= 2, 0 <= z <= 2) spinning
    # 90 degrees per frame about z, through particles at rest at mid height (no gravity,
    # friction 0). In the door's frame a particle turns back towards the half that sweeps it,
    # so it stays on its side of the door's plane: local y keeps its sign. Pushed by the door,
    # it moves straight outwards between hits (its radius never shrinks), so a particle that
    # ends within the door's radius never went around its tip: its side may not change.
    half = 2.0
    grid = grid_mesh(9, 1.0)
    verts = np.column_stack([(grid.vertices[:, 0] - 0.5) * 2 * half, np.zeros(len(grid.vertices)),
                             grid.vertices[:, 1] * 2.0])
    rng = np.random.default_rng(5)
    n = 300
    r = rng.uniform(0.2, 0.9 * half, n)
    phi = rng.uniform(0.05, math.pi - 0.05, n)  # never exactly on the door at the start
    phi += np.where(rng.random(n) < 0.5, 0.0, math.pi)
    x0 = np.column_stack([r * np.cos(phi), r * np.sin(phi), rng.uniform(0.3, 1.7, n)])
    model = _model()
    state = model.state()
    _place(state, x0, np.zeros((n, 3)))
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps=1)
    step = math.pi / 2
    hits = 0
    side = np.sign(x0[:, 1])
    for f in range(12):
        m0, m1 = _rotation([0, 0, 1], step * f), _rotation([0, 0, 1], step * (f + 1))
        door = _mesh_collider("Door", verts, grid.triangles, m0, m1, restitution=0.3,
                              friction=0.0)
        hits += solver.advance(state, _inputs(f, [door], gravity=(0, 0, 0))).collisions
        local = state.particle_x @ np.linalg.inv(m1)[:3, :3].T
        inside_radius = np.hypot(local[:, 0], local[:, 1]) < 0.98 * half
        crossed = inside_radius & (local[:, 1] * side <= 0.0)
        assert not crossed.any(), f"frame {f}: {crossed.sum()} particles crossed the door"
        side = np.sign(local[:, 1])
        np.testing.assert_allclose(state.particle_x[:, 2], x0[:, 2])  # pushed horizontally
    assert hits >= n  # every particle was swept at least once


def test_deforming_mesh_lifts_resting_particles():
    # The ground's vertices rise 0.3 m during one frame (vertices1 = vertices0 + 0.3 up): the
    # particles resting on it are lifted (side tracking: the mesh crossed them, no segment did)
    # and end above it, with the surface's speed 0.3 / DT plus the bounce, then land again.
    verts, tris = _sheet(11, 10.0)
    model = _model()
    state = model.state()
    rng = np.random.default_rng(7)
    n = 50
    _place(state, np.column_stack([rng.uniform(-4, 4, (n, 2)), np.full(n, SKIN)]),
           np.zeros((n, 3)))
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps=2)
    flat = _mesh_collider("Ground", verts, tris, restitution=0.0, friction=0.5)
    for f in range(3):  # resting
        solver.advance(state, _inputs(f, [flat]))
        np.testing.assert_allclose(state.particle_x[:, 2], SKIN, atol=1e-12)
    raised = verts + [0.0, 0.0, 0.3]
    lift = _mesh_collider("Ground", verts, tris, verts1=raised, restitution=0.0, friction=0.5)
    report = solver.advance(state, _inputs(3, [lift]))
    assert report.collisions == n
    assert np.all(state.particle_x[:, 2] >= 0.3)
    assert np.all(state.particle_v[:, 2] > 0.3 / DT * 0.9)  # carried at the surface's speed
    top = _mesh_collider("Ground", raised, tris, restitution=0.0, friction=0.5)
    for f in range(4, 40):
        solver.advance(state, _inputs(f, [top]))
        assert np.all(state.particle_x[:, 2] >= 0.3)
    np.testing.assert_allclose(state.particle_x[:, 2], 0.3 + SKIN, atol=1e-9)


# -- rest and friction ------------------------------------------------------------------------

# the bounce height on a mesh ground: test_particles_closed_forms.py, shared with the half space

def test_resting_on_mesh_ground_does_not_sink_or_jitter():
    verts, tris = _sheet(6, 20.0)
    ground = _mesh_collider("Ground", verts, tris, restitution=0.5, friction=0.5)
    model = _model()
    state = model.state()
    _place(state, [0.7, 0.4, 0.5], [0.0, 0.0, 0.0])
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps=2)
    for f in range(60):
        solver.advance(state, _inputs(f, [ground]))
        assert state.particle_x[0, 2] >= 0.0
    heights = []
    for f in range(60, 160):
        solver.advance(state, _inputs(f, [ground]))
        heights.append(state.particle_x[0, 2])
        assert abs(state.particle_v[0, 2]) < 1e-9
    heights = np.array(heights)
    assert heights.min() >= 0.0
    assert heights.max() - heights.min() <= SKIN
    assert heights.max() <= 2 * SKIN


def test_mesh_thickness_keeps_particles_that_far_from_the_surface():
    verts, tris = _sheet(4, 20.0)
    ground = _mesh_collider("Ground", verts, tris, m0=_translate(z=0.5), restitution=0.0,
                            friction=0.5, thickness=0.05)
    model = _model()
    state = model.state()
    _place(state, [[0.0, 0.0, 1.0], [1.0, 2.0, 3.0]], np.zeros((2, 3)))
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps=4)
    for f in range(60):
        solver.advance(state, _inputs(f, [ground]))
        assert np.all(state.particle_x[:, 2] >= 0.55)
    np.testing.assert_allclose(state.particle_x[:, 2], 0.55, atol=2 * SKIN)
    assert np.all(np.abs(state.particle_v[:, 2]) < 1e-9)


THETA = math.radians(30.0)


def _slope(mu):
    m = _rotation([1, 0, 0], THETA)
    normal = m[:3, 2]
    downhill = np.array([0.0, -math.cos(THETA), -math.sin(THETA)])
    verts, tris = _sheet(7, 60.0)
    return _mesh_collider("Slope", verts, tris, m, restitution=0.0, friction=mu), normal, downhill


def test_static_friction_holds_on_sloped_mesh():
    # mu > tan(theta): at most one sub-step slips before friction engages (<= g sin h^2).
    mu = 0.8
    slope, normal, downhill = _slope(mu)
    model = _model()
    state = model.state()
    _place(state, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps=1)
    heights = []
    for f in range(100):
        solver.advance(state, _inputs(f, [slope]))
        x, v = state.particle_x[0], state.particle_v[0]
        heights.append(x @ normal)
        assert x @ normal >= -1e-12
        assert abs(v @ normal) < 1e-9
    assert max(heights) - min(heights) <= SKIN + 1e-12
    assert np.linalg.norm(state.particle_x[0]) <= G * math.sin(THETA) * DT * DT
    assert np.linalg.norm(state.particle_v[0]) < 1e-6


def test_sliding_on_sloped_mesh_accelerates_at_coulomb_rate():
    # mu < tan(theta): a = g (sin - mu cos) along the slope, across the mesh's interior edges
    # (coplanar triangles: the same normal everywhere), exact to rounding.
    mu = 0.2
    slope, normal, downhill = _slope(mu)
    model = _model()
    state = model.state()
    _place(state, -10.0 * downhill, [0.0, 0.0, 0.0])  # 10 m uphill of the centre
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps=2)
    speeds = {}
    for f in range(50):
        solver.advance(state, _inputs(f, [slope]))
        v = state.particle_v[0]
        assert -1e-12 <= state.particle_x[0] @ normal <= SKIN + 1e-12
        assert abs(v @ normal) < 1e-9
        speeds[f] = v @ downhill
    expected = G * (math.sin(THETA) - mu * math.cos(THETA))
    measured = (speeds[45] - speeds[15]) / (30 * DT)
    assert measured == pytest.approx(expected, rel=1e-9)


def test_large_flat_mesh_matches_the_half_space():
    # Particles dropped and thrown onto a large flat grid and onto HALF_SPACE: the same bounces
    # (time of impact by signed volumes vs by z: rounding apart) and the same rest.
    rng = np.random.default_rng(11)
    n = 40
    x0 = np.column_stack([rng.uniform(-3, 3, (n, 2)), rng.uniform(0.1, 3.0, n)])
    v0 = rng.normal(size=(n, 3)) * [2.0, 2.0, 4.0]
    verts, tris = _sheet(9, 200.0)
    results = []
    for ground in (_mesh_collider("Ground", verts, tris, restitution=0.6, friction=0.3),
                   ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4), restitution=0.6,
                                 friction=0.3)):
        model = _model()
        state = model.state()
        _place(state, x0, v0)
        solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps=4)
        track = []
        for f in range(72):
            solver.advance(state, _inputs(f, [ground]))
            track.append(state.particle_x.copy())
        results.append(np.array(track))
    mesh_track, plane_track = results
    assert mesh_track[:, :, 2].min() >= 0.0
    np.testing.assert_allclose(mesh_track, plane_track, atol=1e-6)


# -- bad input ----------------------------------------------------------------------------------

def test_bad_mesh_input_is_named():
    verts, tris = _sheet(3, 1.0)
    bad = verts.copy()
    bad[4, 1] = np.nan
    with pytest.raises(ValueError, match=r'"Wall".*vertices0 vertex 4 is not finite'):
        _mesh_collider("Wall", bad, tris)
    with pytest.raises(ValueError, match=r"vertices1 vertex 4 is not finite: \[.*nan"):
        _mesh_collider("Wall", verts, tris, verts1=bad)
    with pytest.raises(ValueError, match="vertices0 has 9 vertices but vertices1 has 8"):
        _mesh_collider("Wall", verts, tris, verts1=verts[:8])
    with pytest.raises(ValueError, match="no triangles"):
        _mesh_collider("Wall", verts, np.zeros((0, 3), np.int64))
    with pytest.raises(ValueError, match=r"triangle 1 refers to vertex \[.*9.*\] but the mesh has 9"):
        _mesh_collider("Wall", verts, np.array([[0, 1, 2], [3, 4, 9]]))
    with pytest.raises(ValueError, match="needs vertices0"):
        ColliderFrame("Wall", "MESH", np.eye(4), np.eye(4), triangles=tris)
    with pytest.raises(ValueError, match="MESH colliders only"):
        ColliderFrame("Ball", "SPHERE", np.eye(4), np.eye(4), triangles=tris)


def test_spring_mesh_vertices_collide_with_a_mesh_ground():
    # Spring meshes reuse the same passes: a cloth dropped on a flat mesh ground rests on it.
    from physanim.core.springs import (SpringFrameInputs, SpringMeshBuilder, SpringMeshSettings,
                                       SpringMeshSolver)
    grid = grid_mesh(9, 1.0)
    x = grid.vertices + [-0.5, -0.5, 0.3]
    edges = np.unique(np.sort(np.concatenate([grid.triangles[:, [0, 1]], grid.triangles[:, [1, 2]],
                                              grid.triangles[:, [2, 0]]]), axis=1), axis=0)
    settings = SpringMeshSettings("Sheet", mass=0.3, stiffness=2000.0, damping=2.0,
                                  shear_stiffness=500.0, bend_stiffness=0.01, drag=0.5)
    t = grid.triangles
    model = SpringMeshBuilder(settings, x, edges, t, 3 * np.arange(len(t)), np.full(len(t), 3),
                              t.ravel()).finalize(1)
    verts, tris = _sheet(5, 10.0)
    ground = _mesh_collider("Ground", verts, tris, restitution=0.0, friction=0.5)
    solver = SpringMeshSolver(model, "IMPLICIT", 2, frame_dt=DT, frame=1)
    state = model.state()
    hits = 0
    for frame in range(1, 49):
        hits += solver.advance(state, SpringFrameInputs(frame, frame * DT, DT, colliders=[ground]))
        assert state.x[:, 2].min() >= -1e-6
    assert hits > 0
    assert state.x[:, 2].max() < 0.01


def test_travelling_waves_never_swallow_resting_particles():
    """A ground whose sine waves keep travelling (its surface rises and falls under every
    particle, up to 2.4 m/s) must carry every particle on top, checked every frame for three
    random layouts. (Before hits on a deforming mesh were restarted on its end-of-step surface,
    ~30 % ended underneath; before a hit's validity was judged on the surface nearest the
    particle rather than the hit triangle's plane, a few in a thousand slipped under next to
    the ridges between triangles.)"""
    for seed in range(3):
        _ride_the_waves(seed)


def _ride_the_waves(seed: int):
    from physanim.core.collision import TriangleMesh, build_bvh, shapes
    from physanim.core.collision.raycast import segment_hits

    grid = shapes.grid_mesh(41, size=8.0)
    base = np.asarray(grid.vertices) - [4.0, 4.0, 0.0]
    tris = np.asarray(grid.triangles)

    def surface(frame):
        v = base.copy()
        v[:, 2] = 0.25 * np.sin(1.5 * v[:, 0] - 0.4 * frame)
        return v

    model = _model()
    state = model.state()
    rng = np.random.default_rng(seed)
    count = 1500
    x = np.column_stack([rng.uniform(-3.0, 3.0, (count, 2)), rng.uniform(0.3, 1.5, count)])
    state.append(0, x, np.zeros_like(x), np.ones(count), np.zeros(count), np.full(count, 1e9),
                 np.ones(count))
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", 3)
    for frame in range(36):
        ground = ColliderFrame("Waves", "MESH", np.eye(4), np.eye(4), 0.3, 0.4,
                               vertices0=surface(frame), vertices1=surface(frame + 1),
                               triangles=tris)
        solver.advance(state, FrameInputs(frame, frame / 24, 1 / 24,
                                          emitters=[EmitterFrame(active=False)],
                                          colliders=[ground]))
        bvh = build_bvh(TriangleMesh(surface(frame + 1), tris), "aabb", "topdown")
        p = state.particle_x
        inner = np.all(np.abs(p[:, :2]) < 3.5, axis=1)  # away from the open boundary
        above = segment_hits(bvh, p[inner], p[inner] + [0.0, 0.0, 5.0])
        assert not above.hit.any(), \
            f"seed {seed}, frame {frame + 1}: {int(above.hit.sum())} of {int(inner.sum())} " \
            "under the waves"


def test_hierarchy_is_reused_for_the_same_mesh_and_refitted_for_a_deformed_one():
    """Frame intervals of one collider share its hierarchy: the same vertices reuse it, moved
    vertices over the same triangles refit it (answers equal to a fresh build), other triangles
    or a same-named other mesh rebuild it."""
    from physanim.core.collision import TriangleMesh, build_bvh
    from physanim.core.collision.raycast import segment_hits
    from physanim.core.contact import mesh as mesh_collider

    verts, tris = _sheet(12, 4.0)
    first = _mesh_collider("Reuse", verts, tris)
    cache = mesh_collider.MeshHierarchies()
    bvh, boundary = cache.of(first)
    again, boundary_again = cache.of(_mesh_collider("Reuse", verts.copy(), tris))
    assert again is bvh and boundary_again is boundary

    moved = verts.copy()
    moved[:, 2] = 0.3 * np.sin(2.0 * moved[:, 0]) + 0.1 * moved[:, 1]
    refit, _ = cache.of(_mesh_collider("Reuse", moved, tris))
    fresh = build_bvh(TriangleMesh(moved, tris), mesh_collider.BVH_KIND, "topdown")
    rng = np.random.default_rng(7)
    a = np.column_stack([rng.uniform(-2, 2, (500, 2)), np.full(500, 2.0)])
    b = a - [0.0, 0.0, 4.0]
    ours, theirs = segment_hits(refit, a, b), segment_hits(fresh, a, b)
    assert ours.hit.all() and np.array_equal(ours.triangle, theirs.triangle)
    np.testing.assert_allclose(ours.point, theirs.point, atol=1e-12)

    other_tris = tris[::-1, ::-1].copy()
    rebuilt, _ = cache.of(_mesh_collider("Reuse", moved, other_tris))
    assert rebuilt is not refit and np.array_equal(rebuilt.mesh.triangles, other_tris)

    # a mesh that keeps deforming is refitted REBUILD_AFTER times, then built afresh
    refits = []
    for k in range(mesh_collider.REBUILD_AFTER + 1):
        shape = moved + [0.0, 0.0, 0.01 * (k + 1)]
        cache.of(_mesh_collider("Reuse", shape, other_tris))
        refits.append(cache._known["Reuse"][4])
    assert refits == list(range(1, mesh_collider.REBUILD_AFTER + 1)) + [0]


def test_deforming_mesh_with_two_sheets_stops_a_particle_at_the_far_one():
    """Two stacked plates in one deforming mesh (both facing up; a corner of the lower one
    moves): a particle just above the lower plate, rising fast, hits the upper plate from
    behind. Its side must be judged on the plate it hits, not on the nearest sheet (the lower
    plate, which it is in front of), or the hit is discarded and it passes through."""
    from physanim.core import contact as coll

    quad = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    v0 = np.concatenate([quad, quad + [0.0, 0.0, 0.1]])
    v1 = v0.copy()
    v1[0, 2] -= 1e-3  # deforming, far from the particle
    tris = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    shelves = _mesh_collider("Shelves", v0, tris, verts1=v1, restitution=0.0, friction=0.0)
    path = coll.ColliderPaths().path(shelves, DT)
    x0, v = np.array([[0.3, 0.2, 0.03]]), np.array([[0.0, 0.0, 6.0]])
    x, v_after, count, _ = coll.respond([path], x0, x0 + DT * v, v, v.copy(), 0.0, 1.0, DT, 0.1)
    assert count == 1
    assert 0.09 < x[0, 2] < 0.1 and v_after[0, 2] <= 0.0


def test_a_particle_between_two_sheets_is_not_pulled_onto_one_by_a_fast_neighbour():
    """A moving mesh finds each particle's side of it within that particle's own reach: a slow
    particle midway between two sheets (half a metre from each), whose nearest sheet changes
    as it drifts up, crossed neither — with or without a fast particle beside it. (The search
    was as wide as the fastest particle's reach: the side change then counted as the mesh
    passing over the slow one, which was put on the upper sheet 0.49 m away.)"""
    from physanim.core.contact import ColliderPaths

    square = np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]], float)
    verts = np.vstack([square, square + [0.0, 0.0, 1.0]])
    tris = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    sliding = np.eye(4)
    sliding[0, 3] = 0.01  # (moving: its sides are tracked)
    frame = ColliderFrame("Sheets", "MESH", np.eye(4), sliding, vertices0=verts,
                          vertices1=verts, triangles=tris)
    path = ColliderPaths().of([frame], DT)[0]
    slow0, slow1 = np.array([[0.0, 0.0, 0.49]]), np.array([[0.0, 0.0, 0.51]])
    fast0, fast1 = np.array([[-1.5, 1.5, 0.25]]), np.array([[1.5, 1.5, 0.25]])  # (between)
    for x0, x1 in ((slow0, slow1), (np.vstack([slow0, fast0]), np.vstack([slow1, fast1]))):
        times = (np.broadcast_to(0.0, (len(x0),)), np.broadcast_to(1.0, (len(x0),)))
        assert len(path.first_hits(x0, x1, *times).index) == 0
    # a particle the sheets do pass over is still found: the lower sheet, lifted 3 cm past it
    lifted = np.eye(4)
    lifted[2, 3] = 0.03
    path = ColliderPaths().of([ColliderFrame("Sheets", "MESH", np.eye(4), lifted,
                                             vertices0=verts, vertices1=verts,
                                             triangles=tris)], DT)[0]
    x = np.array([[0.0, 0.0, 0.01], [1.5, 1.5, -3.0]])
    times = (np.broadcast_to(0.0, (2,)), np.broadcast_to(1.0, (2,)))
    hits = path.first_hits(x, x + [[0.0, 0.0, 0.0], [0.0, 0.0, 1.5]], *times)
    assert hits.index.tolist() == [0]  # (where its path crosses the sheet, in its frame)


def test_a_particle_flying_round_an_acute_edge_of_a_closed_mesh_is_not_hit(monkeypatch):
    """Which side of a closed mesh a point is on is judged by the pseudo-normal of its nearest
    feature: a particle flying past a tetrahedron's edge 3 m outside it stays outside on both
    sides of the edge (by the nearest triangle's own face normal it was behind one face, and
    the side change counted as the moving mesh passing over it: it was put on the edge)."""
    from physanim.core.contact import ColliderPaths

    verts = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float)
    tris = np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])  # closed, outward
    moved = np.eye(4)
    moved[0, 3] = 0.01
    path = ColliderPaths().of([ColliderFrame("Tet", "MESH", np.eye(4), moved, vertices0=verts,
                                             vertices1=verts, triangles=tris)], DT)[0]
    n1, n2 = np.array([1.0, 1.0, -1.0]), np.array([1.0, -1.0, 1.0])  # the edge's two faces

    def out(a):
        d = a * n1 + (1.0 - a) * n2
        return np.array([1.0, 0.0, 0.0]) + 3.0 * d / np.linalg.norm(d)
    x0, x1 = np.array([out(a) for a in (0.9, 0.8, 0.7)]), np.array([out(a) for a in
                                                                      (0.05, 0.1, 0.2)])
    times = (np.broadcast_to(0.0, (3,)), np.broadcast_to(1.0, (3,)))
    assert len(path.first_hits(x0, x1, *times).index) == 0
    monkeypatch.setattr(type(path), "sweep_rows", lambda self, *args: None)  # every segment
    assert len(path.first_hits(x0, x1, *times).index) == 0  # tested: still none


def test_a_mesh_flipping_its_scale_within_a_frame_keeps_its_thickness(monkeypatch):
    """A mesh animated from scale x = 1 to x = -1 over the frame is thin in x midway: a world
    metre spans far more of its local units there than at either end. A particle ending
    7.9 mm off it (its thickness 10 mm) over a sub-step there is a hit, with the world cut of
    segments as with every segment tested (that cut was grown by the ends' metre: it dropped
    the particle)."""
    from physanim.core.contact import ColliderPaths

    h = 5e-4
    verts = np.array([(x, y, z) for x in (-h, h) for y in (-h, h) for z in (-h, h)])
    tris = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                     [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    frame = ColliderFrame("Flip", "MESH", np.eye(4), np.diag([-1.0, 1.0, 1.0, 1.0]),
                          thickness=0.01, vertices0=verts, vertices1=verts, triangles=tris)
    path = ColliderPaths().of([frame], DT)[0]
    s0, s1 = 0.49, 0.4901
    x0 = (path.path.matrices(s0)[:3, :3] @ [0.79, 0.0, 0.0])[None]
    x1 = (path.path.matrices(s1)[:3, :3] @ [0.40, 0.0, 0.0])[None]
    far = np.array([[3.0, 3.0, 3.0]])  # (and one far off: a cut is made)
    x0, x1 = np.vstack([x0, far]), np.vstack([x1, far])
    times = (np.broadcast_to(s0, (2,)), np.broadcast_to(s1, (2,)))
    assert path.first_hits(x0, x1, *times).index.tolist() == [0]
    assert path.sweep_rows(x0, x1, *times).tolist() == [0]
    monkeypatch.setattr(type(path), "sweep_rows", lambda self, *args: None)
    assert path.first_hits(x0, x1, *times).index.tolist() == [0]


def test_one_shape_over_the_frame_is_checked_once_and_kept_one():
    """A mesh collider given one vertex array for both ends of the frame (a rigid body's
    shape) keeps one checked array: its path knows it does not deform without comparing
    them, and moves it as a whole; a bad vertex in it is named as ever."""
    from physanim.core.contact import ColliderPaths
    from physanim.core.errors import PhysanimError

    grid = grid_mesh(4, 1.0, 0.1)
    verts, tris = np.array(grid.vertices), np.array(grid.triangles)
    moved = np.eye(4)
    moved[2, 3] = 0.05
    frame = ColliderFrame("Rock", "MESH", np.eye(4), moved, vertices0=verts, vertices1=verts,
                          triangles=tris)
    assert frame.vertices1 is frame.vertices0 and not frame.vertices0.flags.writeable
    path = ColliderPaths().of([frame], DT)[0]
    assert not path.deforming and path.max_step == 0.0 and not path.vertex_step.any()
    copied = ColliderFrame("Rock", "MESH", np.eye(4), moved, vertices0=verts,
                           vertices1=verts.copy(), triangles=tris)
    assert not ColliderPaths().of([copied], DT)[0].deforming  # (the same values: no motion)
    bad = verts.copy()
    bad[3, 1] = np.nan
    with pytest.raises((ValueError, PhysanimError), match="vertices0 vertex 3 is not finite"):
        ColliderFrame("Rock", "MESH", np.eye(4), moved, vertices0=bad, vertices1=bad,
                      triangles=tris)


def test_every_mesh_collider_of_a_frame_keeps_its_hierarchy(monkeypatch):
    """Twenty moving mesh colliders (rigid bodies' hulls as particles meet them) build their
    hierarchies once for the run, not every frame (a cache of eight colliders was emptied and
    refilled by each frame's twenty: 4 ms per collider and frame); a collider gone from the
    scene is dropped once the others need the room."""
    from physanim.core.contact import ColliderPaths
    from physanim.core.contact import mesh_hierarchies as mesh_

    built = []
    build = mesh_.build_bvh
    monkeypatch.setattr(mesh_, "build_bvh", lambda *a, **k: built.append(1) or build(*a, **k))
    rock = grid_mesh(3, 0.5, 0.1)
    verts, tris = np.array(rock.vertices), np.array(rock.triangles)
    paths = ColliderPaths()

    def frames(count, f):
        out = []
        for k in range(count):
            m0, m1 = np.eye(4), np.eye(4)
            m0[:3, 3], m1[:3, 3] = (k, 0.0, 0.1 * f), (k, 0.0, 0.1 * (f + 1))
            out.append(ColliderFrame(f"Rock{k}", "MESH", m0, m1, vertices0=verts,
                                     vertices1=verts, triangles=tris))
        return out
    for f in range(5):
        paths.of(frames(20, f), DT)
    assert len(built) == 20
    for f in range(5, 8):  # twelve rocks gone: eight kept, the others dropped as room is needed
        paths.of(frames(8, f), DT)
    assert len(built) == 20 and len(paths.hierarchies) == 20
    paths.of([ColliderFrame("Other", "MESH", np.eye(4), np.eye(4), vertices0=verts,
                            vertices1=verts, triangles=tris)], DT)
    assert len(built) == 21 and len(paths.hierarchies) <= 20
    # a frame asks twice (the scene's colliders, then with the rigid bodies'): a collider new
    # in the first ask does not push the second's out
    again = ColliderPaths()
    built.clear()
    for f in range(4):
        scene = [ColliderFrame(f"Ground{f}", "MESH", np.eye(4), np.eye(4), vertices0=verts,
                               vertices1=verts, triangles=tris)]
        again.of(scene, DT)
        again.of(scene + frames(20, f), DT)
    assert len(built) == 20 + 4


def _mesh_path(name, verts, tris, moved: bool, thickness: float):
    from physanim.core.contact import ColliderPaths

    m1 = np.eye(4)
    m1[1, 3] = 1e-6 if moved else 0.0
    return ColliderPaths().of([ColliderFrame(name, "MESH", np.eye(4), m1, thickness=thickness,
                                             vertices0=verts, vertices1=verts,
                                             triangles=tris)], DT)[0]


@pytest.mark.parametrize("moved", [False, True])
def test_contact_normals_face_the_particle_whatever_the_mesh_is_made_of(moved):
    """A contact's normal is the nearest face turned to the particle: on a pyramid's apex
    whose nearest triangle has no area (a face split at one edge, its gap closed by a
    zero-area triangle) and on a roof ridge one of whose faces is wound the other way, a
    particle falling onto the mesh is put on it, outside, moving up (judged by the surface
    around the apex or the ridge, the zero-area face gave a zero normal and NaN, and the
    flipped face one pointing into the roof)."""
    from physanim.core.contact import respond

    pyramid = (np.array([[0, 0, 0], [1, 1, -1], [-1, 1, -1], [-1, -1, -1], [1, -1, -1],
                         [0.5, 0.5, -0.5]], float),
               np.array([[0, 5, 1], [0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5], [5, 4, 1],
                         [1, 4, 3], [1, 3, 2]]), 0.0)
    roof = (np.array([[0, -1, 0], [0, 1, 0], [-1, 0, -0.5], [1, 0, -0.5]], float),
            np.array([[0, 1, 2], [0, 1, 3]]), 5e-4)
    for verts, tris, off in (pyramid, roof):
        path = _mesh_path("Mesh", verts, tris, moved, 0.01)
        x0 = np.array([[off, 0.0, 0.05]])
        v = np.array([[0.0, 0.0, -0.045 / DT]])
        done = respond([path], x0, x0 + DT * v, v, v.copy(), 0.0, 1.0, DT, 0.1)
        assert done.count == 1 and np.isfinite(done.x).all() and np.isfinite(done.v).all()
        assert done.x[0, 2] > 0.0 and done.v[0, 2] > 0.0  # above the apex or ridge, going up
        near = path.near_surface(np.array([[off, 0.0, 0.0105]]), 1.0)
        assert np.isfinite(near.normal).all() and (near.normal[:, 2] > 0.0).all()
