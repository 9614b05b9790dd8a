"""Rigid bodies in a Mesh collider: an open bowl (the lower half of a sphere's mesh)."""
from __future__ import annotations

import numpy as np

from physanim.core.contact import ColliderFrame
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
