"""Concave Mesh bodies: rings over a peg (what no convex hull can do), rings on rings (Mesh
against Mesh, both moving), a ring on a box body and on the ground, momentum in Mesh-Mesh
collisions, and the signed distances to convex shapes the Mesh vertices are tested with."""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.collision.build import build_bvh
from physanim.core.collision.distance import closest_points
from physanim.core.collision.shapes import cylinder_mesh, torus_mesh
from physanim.core.contact import ColliderFrame
from physanim.core.errors import PhysanimError
from physanim.core.rigid import quaternion as quat
from physanim.core.rigid.mass import polyhedron_mass
from physanim.core.rigid.model import RigidBodySettings
from physanim.tests.core.rigid_helpers import DT, box, ground, run, sphere, world

MAJOR, MINOR = 0.5, 0.1  # [m] the rings' radius and tube radius
PEG_RADIUS, PEG_HALF = 0.15, 0.6  # [m]
TORUS = torus_mesh(MAJOR, MINOR, 40, 12)


def ring(name, position, tilt=0.0, shape="MESH", **kw) -> RigidBodySettings:
    q = quat.from_rotation_vector(np.array([[tilt, 0.0, 0.0]]))[0]
    geometry = {"mesh": (TORUS.vertices, TORUS.triangles)} if shape == "MESH" else \
        {"hull": TORUS.vertices}
    return RigidBodySettings(name, shape, polyhedron_mass(TORUS.vertices, TORUS.triangles,
                                                          mass=1.0),
                             position=tuple(position), orientation=tuple(q), **geometry, **kw)


def peg() -> ColliderFrame:
    c = cylinder_mesh(PEG_RADIUS, PEG_HALF, 24)
    m = np.eye(4)
    m[2, 3] = PEG_HALF
    return ColliderFrame("Peg", "MESH", m, m, 0.0, 0.5, vertices0=c.vertices,
                         vertices1=c.vertices, triangles=c.triangles)


def _world_vertices(model, state, i):
    r = quat.to_matrix(state.body_q[i:i + 1])[0]
    return model.body_mesh[i][0] @ r.T + state.body_x[i]


def _deepest_inside(points, mesh_vertices, mesh_triangles) -> float:
    """How deep [m] the deepest of ``points`` lies inside a closed mesh (0: none inside)."""
    from physanim.core.collision.mesh import TriangleMesh
    bvh = build_bvh(TriangleMesh(mesh_vertices, mesh_triangles, name="m"), "aabb")
    sd = closest_points(bvh, points).signed_distance
    return float(max(0.0, -sd.min()))


def _ring_in_ring(model, state, i, j) -> float:
    """Deepest vertex of ring i inside ring j [m]."""
    r = quat.to_matrix(state.body_q[j:j + 1])[0]
    local = (_world_vertices(model, state, i) - state.body_x[j]) @ r
    return _deepest_inside(local, *model.body_mesh[j])


def _in_peg(model, state, i) -> float:
    c = cylinder_mesh(PEG_RADIUS, PEG_HALF, 24)
    return _deepest_inside(_world_vertices(model, state, i) - (0, 0, PEG_HALF), c.vertices,
                           c.triangles)


def test_a_ring_at_the_defaults_rests_flat_on_the_ground():
    # nothing set but the shape: the lowest row of vertices carries it, not the wider row above
    model, solver, state = world(ring("Ring", (0.0, 0.0, 0.5)))
    run(solver, state, int(1.5 / DT), colliders=[ground()])
    lowest = _world_vertices(model, state, 0)[:, 2].min()
    assert abs(lowest) < 1e-3, lowest
    assert abs(state.body_x[0, 2] - MINOR) < 1e-3


def test_a_ring_dropped_over_a_peg_slides_down_it():
    model, solver, state = world(ring("Ring", (0.1, 0.05, 1.6), tilt=0.15))
    run(solver, state, int(3.0 / DT), colliders=[ground(), peg()])
    assert abs(state.body_x[0, 2] - MINOR) < 2e-3  # on the ground, around the peg
    assert np.hypot(*state.body_x[0, :2]) < MAJOR - MINOR - PEG_RADIUS + 1e-3
    assert _in_peg(model, state, 0) < 2e-3


def test_as_its_convex_hull_a_ring_lands_on_the_peg_instead():
    # the same ring as a hull (a disc) dropped square onto the peg: the peg's top rim (its
    # vertices against the hull's faces) holds it
    for shape, rests_at in (("HULL", 2 * PEG_HALF + MINOR), ("MESH", MINOR)):
        model, solver, state = world(ring("Ring", (0.0, 0.0, 1.6), shape=shape))
        run(solver, state, int(2.0 / DT), colliders=[ground(), peg()])
        assert state.body_x[0, 2] == pytest.approx(rests_at, abs=3e-3), shape


def test_three_rings_over_a_peg_stack_without_passing_through_each_other():
    bodies = [ring(f"Ring{k}", (0.1 * (k % 2), 0.05, 1.6 + 0.5 * k), tilt=0.15 * (-1) ** k)
              for k in range(3)]
    model, solver, state = world(*bodies)
    worst = []

    def each(frame, s):
        worst.append(max(_ring_in_ring(model, s, i, j) for i in range(3) for j in range(3)
                         if i != j))
    run(solver, state, int(4.0 / DT), colliders=[ground(), peg()], each=each)
    assert max(worst) < 5e-3, max(worst)
    assert max(_in_peg(model, state, i) for i in range(3)) < 5e-3
    z = np.sort(state.body_x[:, 2])
    assert z[0] == pytest.approx(MINOR, abs=2e-3) and z[1] > z[0] + MINOR and z[2] > z[1]
    # every ring is around the peg: the peg's axis passes through its hole
    for i in range(3):
        r = quat.to_matrix(state.body_q[i:i + 1])[0]
        axis_local = (np.array([0.0, 0.0, state.body_x[i, 2]]) - state.body_x[i]) @ r
        assert np.hypot(*axis_local[:2]) < MAJOR - MINOR
    assert np.abs(np.linalg.norm(state.body_P, axis=1)).max() < 1e-2


def test_a_ring_lands_on_a_box_body_and_a_ball_in_a_ring_rests_in_its_hole():
    crate = box("Crate", (0.6, 0.6, 0.25), (0.0, 0.0, 0.25), mass=5.0)
    model, solver, state = world(crate, ring("Ring", (0.0, 0.0, 1.2)),
                                 sphere("Ball", 0.2, (0.0, 0.0, 2.0)))
    run(solver, state, int(3.0 / DT), colliders=[ground()])
    assert state.body_x[1, 2] == pytest.approx(0.5 + MINOR, abs=3e-3)  # on the crate's top
    lowest = _world_vertices(model, state, 1)[:, 2].min()
    assert lowest > 0.5 - 3e-3
    # the ball (bigger than the hole's 0.4 m radius? no: 0.2 < 0.4) sits in the hole on the
    # crate, touching the ring's inside or the crate: never inside the ring's tube
    r = quat.to_matrix(state.body_q[1:2])[0]
    centre_local = (state.body_x[2] - state.body_x[1]) @ r
    bvh = build_bvh(TORUS, "aabb")
    assert closest_points(bvh, centre_local[None]).signed_distance[0] > 0.2 - 3e-3
    assert state.body_x[2, 2] == pytest.approx(0.5 + 0.2, abs=3e-3)


def test_mesh_mesh_collisions_conserve_momentum():
    free = {"linear_damping": 0.0, "angular_damping": 0.0}
    a = ring("A", (-1.0, 0.0, 0.0), velocity=(3.0, 0.0, 0.0), angular_velocity=(0, 2.0, 1.0),
             **free)
    b = ring("B", (0.55, 0.0, 0.2), tilt=1.2, velocity=(-1.0, 0.5, 0.0), **free)
    model, solver, state = world(a, b)
    p0, l0 = state.body_P.sum(axis=0), _angular_momentum(state)
    touched = []
    run(solver, state, 24, gravity=(0.0, 0.0, 0.0),
        each=lambda f, s: touched.append(np.abs(s.body_P[1] - b.velocity * np.ones(3)).max()))
    assert max(touched) > 0.1  # they did collide
    assert np.abs(state.body_P.sum(axis=0) - p0).max() < 1e-9
    assert np.abs(_angular_momentum(state) - l0).max() < 1e-9


def _angular_momentum(state) -> np.ndarray:
    return (np.cross(state.body_x, state.body_P) + state.body_L).sum(axis=0)


def test_a_mesh_body_needs_its_mesh():
    with pytest.raises(PhysanimError, match="vertices and triangles"):
        RigidBodySettings("Ring", "MESH", polyhedron_mass(TORUS.vertices, TORUS.triangles,
                                                          mass=1.0))
    with pytest.raises(PhysanimError, match="triangles indexing"):
        RigidBodySettings("Ring", "MESH", polyhedron_mass(TORUS.vertices, TORUS.triangles,
                                                          mass=1.0),
                          mesh=(TORUS.vertices, TORUS.triangles + len(TORUS.vertices)))
