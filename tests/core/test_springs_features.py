"""Spring meshes against colliders by faces and edges: a collider's corners, creases and spheres
are kept off a mesh's triangles and edges, so a collider smaller than the mesh's faces — a
sphere, a cone's tip, a thin rod — never passes between its vertices.

"Inside" is checked exactly, every frame: no mesh triangle overlaps a collider triangle (the
library's exact triangle-triangle test; touching counts as overlap). For the analytic sphere:
no mesh triangle comes nearer its centre than its radius (1e-6 m for rounding).
"""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.collision.distance import closest_on_triangles
from physanim.core.collision.raycast import segment_triangle
from physanim.core.collision.shapes import box_mesh, cylinder_mesh
from physanim.core.collision.tritri import triangles_overlap
from physanim.core.contact import ColliderFrame
from physanim.core.springs import (SpringFrameInputs, SpringMeshBuilder, SpringMeshSettings,
                                   SpringMeshSolver)
from physanim.tests.core.helpers import grid, implicit_step_times

DT = 1.0 / 24.0
TOP = 0.6  # every collider's top [m]


def _cube():
    """A low-poly cube (8 vertices, 12 triangles, its 12 edges) 0.5 m wide, 0.6 m above the
    colliders' top."""
    mesh = box_mesh(0.25)
    tris = mesh.triangles
    sides = np.unique(np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]),
                              axis=1), axis=0)
    d = mesh.vertices[sides[:, 0]] - mesh.vertices[sides[:, 1]]
    edges = sides[(np.abs(d) > 1e-9).sum(axis=1) == 1]  # not the faces' diagonals
    return mesh.vertices + (0.0, 0.0, TOP + 0.85), edges, tris


def _sheet(n: int):
    """An n x n grid 1 m wide, 0.4 m above the colliders' top."""
    x, edges, tris, *_ = grid(n, n, 1.0)
    return x + (-0.5, -0.5, TOP + 0.4), edges, tris


MESHES = {"cube": _cube, "plane": lambda: _sheet(2), "cloth": lambda: _sheet(11)}


def _cone(radius=0.3, height=TOP, segments=16):
    t = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = np.stack([radius * np.cos(t), radius * np.sin(t), np.zeros(segments)], axis=1)
    verts = np.concatenate([ring, [(0.0, 0.0, height), (0.0, 0.0, 0.0)]])
    k = np.arange(segments)
    k1 = (k + 1) % segments
    tris = np.concatenate([np.stack([k, k1, np.full(segments, segments)], 1),
                           np.stack([k1, k, np.full(segments, segments + 1)], 1)])
    return np.eye(4), verts, tris


def _rod(radius=0.01):
    """A 2 m rod 2 cm thick along y, its top at TOP."""
    rod = cylinder_mesh(radius, 1.0, 12)
    m = np.eye(4)
    m[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    m[2, 3] = TOP - radius
    return m, rod.vertices, rod.triangles


def _collider(kind: str, **surface) -> ColliderFrame:
    if kind == "sphere":
        m = np.diag([0.3, 0.3, 0.3, 1.0])
        m[:3, 3] = (0.0, 0.0, TOP - 0.3)
        return ColliderFrame("Ball", "SPHERE", m, m, **surface)
    m, verts, tris = _cone() if kind == "cone" else _rod()
    return ColliderFrame(kind, "MESH", m, m, vertices0=verts, vertices1=verts, triangles=tris,
                         **surface)


def _inside(collider: ColliderFrame, x: np.ndarray, tris: np.ndarray):
    """How far the collider is inside the mesh at positions x: the count of overlapping
    triangle pairs (a mesh collider), or how much nearer the sphere's centre a triangle is
    than its radius [m] (<= 0: none)."""
    if collider.shape == "SPHERE":
        centre, radius = collider.matrix0[:3, 3], collider.matrix0[0, 0]
        d2 = closest_on_triangles(np.broadcast_to(centre, (len(tris), 3)).copy(), x[tris])[1]
        return radius - float(np.sqrt(d2.min()))
    m = collider.matrix0
    return _overlaps(x, tris, collider.vertices0 @ m[:3, :3].T + m[:3, 3], collider.triangles)


def _overlaps(x, tris, verts, vtris) -> int:
    """Overlapping pairs of triangles of two meshes (world vertices, triangles)."""
    a, b = np.meshgrid(np.arange(len(tris)), np.arange(len(vtris)), indexing="ij")
    return int(triangles_overlap(x[tris][a.ravel()], verts[vtris][b.ravel()]).sum())


def _drop(mesh: str, collider: ColliderFrame, frames: int, substeps: int = 2):
    x, edges, tris = MESHES[mesh]()
    model = SpringMeshBuilder(SpringMeshSettings(mesh), x, edges, tris).finalize(1)
    solver = SpringMeshSolver(model, "IMPLICIT", substeps, frame_dt=DT, frame=1)
    state = model.state()
    for frame in range(1, frames + 1):
        solver.advance(state, SpringFrameInputs(frame, frame * DT, DT, colliders=[collider]))
        yield state.x.copy(), tris


@pytest.mark.parametrize("collider", ["sphere", "cone", "rod"])
@pytest.mark.parametrize("mesh", ["cube", "plane", "cloth"])
def test_a_mesh_dropped_on_a_small_collider_never_has_it_inside(mesh, collider):
    """Every mesh and collider at their defaults: the sphere (0.6 m across), the cone's tip
    and the rod (2 cm thick) are narrower than the plane's and the cube's faces, so without
    faces and edges colliding they would pass straight between the vertices. They are never
    inside the mesh, and they catch it: a quarter of a second after the collider's top is
    first reached, the mesh still reaches above it (falling through, it would be 0.7 m
    lower)."""
    c = _collider(collider)
    touched = None
    for frame, (x, tris) in enumerate(_drop(mesh, c, 72), start=1):
        inside = _inside(c, x, tris)
        assert inside <= (1e-6 if collider == "sphere" else 0), \
            f"frame {frame}: the {collider} is inside the {mesh} ({inside})"
        if touched is None and x[:, 2].min() < TOP:
            touched = frame
        if touched is not None and frame == touched + 6:
            assert x[:, 2].max() > TOP, f"the {mesh} fell past the {collider}"
    assert touched is not None


@pytest.mark.parametrize("collider", ["sphere", "cone", "rod"])
@pytest.mark.parametrize("mesh", ["plane", "cloth"])
def test_a_mesh_dropped_on_a_grippy_small_collider_rests_on_it(mesh, collider):
    """On a grippy surface (friction 1) the plane and the cloth come to rest on the sphere,
    the cone's tip and the rod: from 1 s to 3 s their highest point stays on the collider's
    top (within 2 cm above it, never below it: they hang from it), the plane still."""
    c = _collider(collider, friction=1.0)
    frames = [x for x, _ in _drop(mesh, c, 72)]
    tops = np.array([x[:, 2].max() for x in frames[23:]])
    assert TOP <= tops.min() and tops.max() < TOP + 0.02, (tops.min(), tops.max())
    if mesh == "plane":
        assert np.abs(frames[-1] - frames[-2]).max() / DT < 1e-2


@pytest.mark.parametrize("where", [(0.01, 0.02), (-0.0051, -0.0547), (0.0177, 0.0441),
                                   (0.0229, 0.0359)])
def test_a_small_sphere_pushed_up_through_a_pinned_cloth_lifts_it_and_never_passes(where):
    """A moving collider: a ball 10 cm across — narrower than the cloth's 12.5 cm cells —
    rises at 1 m/s into a cloth pinned at its four corners, at places in a cell where the
    tightening tent once slid over the ball so fast that a face swept through it whole
    between two frames. It never comes nearer a triangle than its radius, it stays under the
    cloth in every frame (a ray straight up from its centre crosses the cloth an odd number
    of times), and it lifts the cloth's middle with it (a tent, 0.3 m high at the end)."""
    x, edges, tris, *_ = grid(9, 9, 1.0)
    x = x + (-0.5, -0.5, 1.0)
    pin = np.zeros(len(x))
    pin[[0, 8, 72, 80]] = 1.0
    model = SpringMeshBuilder(SpringMeshSettings("Sheet", bend_stiffness=0.0), x, edges, tris,
                              pin_weight=pin).finalize(1)
    solver = SpringMeshSolver(model, "IMPLICIT", 2, frame_dt=DT, frame=1)
    state = model.state()
    radius = 0.05

    def ball(z):
        m = np.diag([radius, radius, radius, 1.0])
        m[:3, 3] = (*where, z)
        return m

    for frame in range(1, 37):  # 1.5 s: from 0.6 m below the cloth to 0.9 m above its level
        z0, z1 = 0.4 + (frame - 1) / 24.0, 0.4 + frame / 24.0
        c = ColliderFrame("Ball", "SPHERE", ball(z0), ball(z1))
        solver.advance(state, SpringFrameInputs(frame, frame * DT, DT, gravity=(0, 0, -9.81),
                                                colliders=[c]))
        centre = np.array([*where, z1])
        d2 = closest_on_triangles(np.broadcast_to(centre, (len(tris), 3)).copy(),
                                  state.x[tris])[1]
        assert np.sqrt(d2.min()) >= radius - 1e-6, f"frame {frame}"
        up = np.broadcast_to(centre, (len(tris), 3))
        hit, _ = segment_triangle(up, up + (0.0, 0.0, 10.0), state.x[tris])
        assert hit.sum() % 2 == 1, f"frame {frame}: the ball is not under the cloth"
    assert state.x[:, 2].max() > 1.3


def test_a_cloth_resting_on_a_cone_tip_is_solved_once_per_sub_step(monkeypatch):
    """A cloth draped on a grippy cone's tip (friction 1, as the resting test above): once it
    rests (from frame 32), each sub-step is solved once. Its faces sag onto the tip by a
    fraction of a millimetre each sub-step; solving the sub-step again with them landing (as
    for a real hit) cost every resting sub-step a second solve, which the features' pass after
    the step makes unnecessary. The tip never gets inside (the first test above), and the cloth
    stays on it."""
    solves = implicit_step_times(monkeypatch)
    c = _collider("cone", friction=1.0)
    frames = [x for x, _ in _drop("cloth", c, 48)]
    times, count = np.unique(np.round(solves, 9), return_counts=True)
    late = count[times > 32 * DT + 1e-6]
    assert len(late) > 30 and late.mean() < 1.1, np.bincount(late)
    tops = np.array([x[:, 2].max() for x in frames[32:]])
    assert TOP <= tops.min() and tops.max() < TOP + 0.02, (tops.min(), tops.max())
    assert np.abs(frames[-1] - frames[-2]).max() / DT < 2e-2  # at rest


def test_a_cloth_dropped_on_a_pyramids_tip_comes_to_rest():
    """A 16 x 16 cloth dropped onto the tip of a pyramid (a mesh collider, friction at its
    default) drapes over it and comes to rest: over the fifth second no vertex moves faster
    than 2 cm/s, half of them slower than 2 mm/s. (When its hanging corners stop swinging
    depends on the drop's path, which rounding on another processor changes: on one machine
    they were still by the third second, on another they swung at up to 19 cm/s in it and
    were still in the fourth.) Its vertices around the tip and along the
    ridges rest through their faces on creases facing ways no one normal stands for; held
    along their pairs' mean normal, each slid into the other creases within the step, was
    pushed back out, and slid in again, every sub-step (the mesh buzzed at 4-10 cm/s and
    never came to rest); wedged there, they are held whole."""
    verts = np.array([(-0.3, -0.3, 0.0), (0.3, -0.3, 0.0), (0.3, 0.3, 0.0), (-0.3, 0.3, 0.0),
                      (0.0, 0.0, TOP)])
    vtris = np.array([(0, 1, 4), (1, 2, 4), (2, 3, 4), (3, 0, 4), (0, 2, 1), (0, 3, 2)])
    pyramid = ColliderFrame("Pyramid", "MESH", np.eye(4), np.eye(4), vertices0=verts,
                            vertices1=verts, triangles=vtris)
    x, edges, tris, *_ = grid(16, 16, 1.0)
    x = x + (-0.487, -0.479, TOP + 0.3)  # (a little off the tip)
    model = SpringMeshBuilder(SpringMeshSettings("Cloth"), x, edges, tris).finalize(1)
    solver = SpringMeshSolver(model, "IMPLICIT", 2, frame_dt=DT, frame=1)
    state = model.state()
    travel, speeds = [], []
    for frame in range(1, 121):
        before = state.x.copy()
        solver.advance(state, SpringFrameInputs(frame, frame * DT, DT, colliders=[pyramid]))
        if frame > 96:
            travel.append(np.linalg.norm(state.x - before, axis=1).max() / DT)
            speeds.append(np.median(np.linalg.norm(state.v, axis=1)))
    assert max(travel) < 0.02 and max(speeds) < 2e-3, (max(travel), max(speeds))
    assert state.x[:, 2].max() > TOP  # on the tip, not slid off
    assert _overlaps(state.x, tris, verts, vtris) == 0


@pytest.mark.parametrize("shape", ["BOX", "PLANE"])
def test_a_coarse_plane_dropped_over_a_box_or_plane_collider_edge_never_has_it_inside(shape):
    """Analytic colliders' corners and edges count too: a 4-vertex plane 1 m wide dropped
    across the edge of a 0.2 m box (or of a bounded plane collider 0.2 m wide) never has
    it inside (none of the collider's visible triangles overlaps the plane's) and is caught
    by it."""
    m = np.diag([0.1, 0.1, 0.1 if shape == "BOX" else 1.0, 1.0])
    m[:3, 3] = (0.0, 0.0, TOP - (0.1 if shape == "BOX" else 0.0))
    c = ColliderFrame("Edge", shape, m, m)
    box = box_mesh(1.0)
    if shape == "BOX":
        verts, vtris = box.vertices @ m[:3, :3].T + m[:3, 3], box.triangles
    else:
        verts = np.array([(-0.1, -0.1, TOP), (0.1, -0.1, TOP), (0.1, 0.1, TOP), (-0.1, 0.1, TOP)])
        vtris = np.array([(0, 1, 2), (0, 2, 3)])
    x, edges, tris = _sheet(2)
    x = x + (0.45, 0.05, 0.0)  # over the collider's edge, most of it beyond
    model = SpringMeshBuilder(SpringMeshSettings("Sheet"), x, edges, tris).finalize(1)
    solver = SpringMeshSolver(model, "IMPLICIT", 2, frame_dt=DT, frame=1)
    state = model.state()
    caught = False
    for frame in range(1, 49):
        solver.advance(state, SpringFrameInputs(frame, frame * DT, DT, colliders=[c]))
        assert _overlaps(state.x, tris, verts, vtris) == 0, f"frame {frame}"
        caught |= bool(state.x[:, 2].min() < TOP - 0.3 and state.x[:, 2].max() > TOP)
    assert caught  # it hung over the edge at some frame, its low side well below the top


@pytest.mark.parametrize("collider", ["sphere", "cone", "rod"])
def test_detections_through_kept_candidate_pairs_equal_fresh_ones(collider):
    # Detections share candidate pairs found once with a margin (NearPairs): every detection
    # gives exactly what a fresh search gives, while the pairs are kept (small moves), found
    # again (a move past the margin) or read with a wider reach.
    from physanim.core.contact import ColliderPaths
    from physanim.core.contact.features import FaceSet, NearPairs, _detect

    rng = np.random.default_rng(3)
    x, edges, tris = _sheet(11)
    x[:, 2] = TOP + 0.002 + 0.01 * rng.random(len(x))  # lying on the collider's top
    faces = FaceSet.of(tris, edges)
    path = ColliderPaths().path(_collider(collider), DT)
    features = path.features(0.0, 0.5)
    near = NearPairs()

    def both(x1, reach=0.0):
        fresh = _detect(path, features, faces, x, x1, 0.0, 0.5, reach)
        kept = _detect(path, features, faces, x, x1, 0.0, 0.5, reach, near=near)
        assert (fresh is None) == (kept is None)
        assert fresh is not None and len(fresh.vertex) > 0
        for a, b in zip(fresh, kept):
            np.testing.assert_array_equal(a, b)
        return [list(k.searches) for k in near._kept.values()]  # searches made (whole, part)

    down = x - (0.0, 0.0, 0.02)  # into the collider's top
    first = both(down)
    assert len(first) == 3
    for _ in range(3):  # small moves: the same kept pairs
        assert both(down + rng.normal(0.0, 1e-4, x.shape)) == first
    assert both(down, reach=0.002) == first  # a reach within the margin
    # past the margin: found again (faces, and edges against creases: the sphere has none;
    # the sheet has no loose edges)
    searched = [0] if collider == "sphere" else [0, 1]
    moved = both(down + (0.05, 0.0, 0.0))
    assert all(moved[k] != first[k] for k in searched)
    wider = both(down + (0.05, 0.0, 0.0), reach=0.2)
    assert all(wider[k] != moved[k] for k in searched)


def test_pairs_at_the_edge_of_the_resting_reach_barely_turn_their_points_normal():
    """A point resting on a collider's features takes its pairs' mean normal; pairs found at
    the far edge of the resting reach (in one sub-step, not the next) turn it by little, so it
    does not swing from one sub-step to the next. Six pairs of a cloth edge and the creases
    meeting at one of Suzanne's corners, 0.97 mm away (of a 1 mm reach), 43 degrees from the
    one touching pair: the normal stays within 3 degrees of the touching pair's. At full
    weight (no reach given) they turn it by over 25 degrees — the drape on Suzanne swung by
    that every sub-step and never came to rest."""
    from types import SimpleNamespace

    from physanim.core.contact.features import _per_point
    from physanim.core.contact.pair_solve import PointPairs

    touching = np.array([0.198, 0.149, 0.969]) / np.linalg.norm([0.198, 0.149, 0.969])
    far = np.array([0.95, 0.026, 0.311]) / np.linalg.norm([0.95, 0.026, 0.311])
    gap, reach, k = 5e-5, 1e-3, 6
    pairs = PointPairs(np.array([[0, 1, 2]] + [[1, 2, 1]] * k),
                       np.array([[0.03, 0.12, 0.85]] + [[0.15, 0.85, 0.0]] * k),
                       np.array([touching] + [far] * k), np.zeros((k + 1, 3)),
                       np.array([gap] + [gap + 0.97 * reach] * k), gap)
    frame = SimpleNamespace(friction=0.3, restitution=0.0)

    def normal_of_point_2(reach):
        contacts = _per_point(pairs, pairs.weight.copy(), np.zeros((k + 1, 3)), 3, frame, 0,
                              None, reach)
        n = contacts.normal[np.flatnonzero(contacts.index == 2)[0]]
        return np.degrees(np.arccos(np.clip(n @ touching, -1.0, 1.0)))

    assert normal_of_point_2(reach) < 3.0
    assert normal_of_point_2(None) > 25.0  # (the weighting before)
