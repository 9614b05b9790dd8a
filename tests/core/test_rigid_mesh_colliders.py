"""Rigid bodies in a Mesh collider: an open bowl (the lower half of a sphere's mesh)."""
from __future__ import annotations

import numpy as np

from physanim.core.contact import ColliderFrame
from physanim.core.rigid import RigidBodySettings
from physanim.core.rigid import quaternion as quat
from physanim.core.rigid.mass import capsule_mass
from physanim.tests.core.rigid_helpers import DT, box, run, sphere, world

RADIUS = 2.0  # [m] the bowl's


def _bowl(segments=32, rings=12) -> ColliderFrame:
    """An open hemispherical bowl of RADIUS, its lowest point at the origin (a scaled object:
    the mesh is a unit bowl, the object's scale makes it RADIUS)."""
    theta = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    phi = np.linspace(np.pi, 0.5 * np.pi, rings + 1)  # bottom pole to the rim
    verts = [(0.0, 0.0, -1.0)]
    for p in phi[1:]:
        verts += [(np.sin(p) * np.cos(t), np.sin(p) * np.sin(t), np.cos(p)) for t in theta]
    verts = np.array(verts)
    tris = [(0, 1 + (k + 1) % segments, 1 + k) for k in range(segments)]
    for r in range(rings - 1):
        a, b = 1 + r * segments, 1 + (r + 1) * segments
        for k in range(segments):
            k1 = (k + 1) % segments
            tris += [(a + k, a + k1, b + k1), (a + k, b + k1, b + k)]
    m = np.diag([RADIUS, RADIUS, RADIUS, 1.0])
    m[2, 3] = RADIUS
    return ColliderFrame("Bowl", "MESH", m, m, 0.0, 0.5, vertices0=verts, vertices1=verts,
                         triangles=np.array(tris))


def test_a_ball_and_a_box_dropped_in_a_bowl_come_to_rest_at_its_bottom():
    ball = sphere("Ball", 0.3, (0.8, 0.0, 2.5))
    crate = box("Crate", (0.2, 0.2, 0.2), (-0.7, 0.3, 3.0))
    model, solver, state = world(ball, crate)
    bowl = _bowl()
    reports = run(solver, state, int(5.0 / DT), colliders=[bowl])
    centre = np.array([0.0, 0.0, RADIUS])
    inside = RADIUS - np.linalg.norm(state.body_x - centre, axis=1)
    assert inside[0] > 0.3 - 0.01  # the ball's surface is inside the bowl's, not through it
    assert inside[1] > 0.2 - 0.01
    assert state.body_x[:, 2].max() < 0.8  # both slid down to the bottom
    assert max(r.overlap for r in reports[12:]) < 0.01
    assert np.linalg.norm(state.body_P[1]) / model.body_mass[1] < 0.01  # the crate is at rest


# --- a ridge: what touches a Mesh collider between its vertices --------------------------------

CREST = 1.0  # [m] the ridge's height


def _ridge() -> ColliderFrame:
    """A roof-shaped Mesh collider: two slopes (1 in 2) meeting at a crest CREST high along y,
    its only vertices 5 m away at the crest's ends (four triangles): whatever lands on the crest
    touches it between vertices, where neither a body's corners nor the mesh's vertices are."""
    verts = np.array([(-2, -5, 0), (0, -5, CREST), (2, -5, 0), (-2, 5, 0), (0, 5, CREST),
                      (2, 5, 0)], float)
    tris = np.array([(0, 1, 4), (0, 4, 3), (1, 2, 5), (1, 5, 4)])
    return ColliderFrame("Ridge", "MESH", np.eye(4), np.eye(4), 0.0, 0.5, vertices0=verts,
                         vertices1=verts, triangles=tris)


def _turn(axis, angle) -> tuple:
    """The unit quaternion turning by ``angle`` [rad] about the unit ``axis``."""
    return tuple(quat.from_rotation_vector(angle * np.asarray(axis, float)).tolist())


def _crest_in_box(x, q, half: float) -> float:
    """[m] how deep the crest line reaches into a cube of ``half`` at pose (x, q) (sampled
    every 5 mm; 0 when it does not)."""
    crest = np.stack([np.zeros(2001), np.linspace(-5.0, 5.0, 2001), np.full(2001, CREST)], 1)
    local = (crest - x) @ quat.to_matrix(np.asarray(q)[None])[0]
    inside = half - np.abs(local)  # per axis; in the box where all three are positive
    return max(0.0, float(inside.min(axis=1).max()))


def test_a_capsule_at_its_defaults_lying_across_a_ridge_rests_on_the_crest():
    """Its axis ends reach past the crest to the slopes: only the crest, between the mesh's
    vertices, holds it (before edges were tested it fell through the ridge)."""
    radius, half = 0.1, 0.5
    capsule = RigidBodySettings("Log", "CAPSULE", capsule_mass(radius, half, mass=1.0),
                                radius=radius, half_extents=(0.0, 0.0, half),
                                position=(0.0, 0.0, 2.0), orientation=_turn((0, 1, 0), np.pi / 2))
    model, solver, state = world(capsule)
    reports = run(solver, state, int(3.0 / DT), colliders=[_ridge()])
    assert abs(state.body_x[0, 2] - (CREST + radius)) < 0.002  # on the crest
    assert max(r.overlap for r in reports) < 0.005
    assert np.linalg.norm(state.body_P[0]) < 0.01


def test_a_box_dropped_on_a_ridge_meets_the_crest_under_its_face():
    """Face down, a little off the crest: it lands on the crest, tips and slides down a slope;
    the crest never reaches more than 5 mm into it (it sank 20 cm onto its corners before)."""
    half = 0.4
    crate = box("Crate", (half, half, half), (0.05, 0.0, 2.0))
    model, solver, state = world(crate)
    deepest = [0.0]

    def each(frame, s):
        deepest[0] = max(deepest[0], _crest_in_box(s.body_x[0], s.body_q[0], half))
    reports = run(solver, state, int(4.0 / DT), colliders=[_ridge()], each=each)
    assert deepest[0] < 0.005
    assert state.body_x[0, 0] > 0.5  # tipped off the crest to the side it leaned to
    assert max(r.overlap for r in reports) < 0.005


def test_a_box_dropped_edge_first_across_a_ridge_balances_where_the_edges_cross():
    """Its lowest edge square across the crest: the two edges touch at one point, between
    every vertex of both; dropped square above the crest, it balances there, its centre
    half a diagonal above the crest (it sank 14 cm into the crest before)."""
    half = 0.4
    crate = box("Crate", (half, half, half), (0.0, 0.02, 2.0),
                orientation=_turn((1, 0, 0), np.pi / 4))
    model, solver, state = world(crate)
    deepest = [0.0]

    def each(frame, s):
        deepest[0] = max(deepest[0], _crest_in_box(s.body_x[0], s.body_q[0], half))
    run(solver, state, int(2.0 / DT), colliders=[_ridge()], each=each)
    assert deepest[0] < 0.005
    assert abs(state.body_x[0, 2] - (CREST + half * np.sqrt(2.0))) < 0.002
