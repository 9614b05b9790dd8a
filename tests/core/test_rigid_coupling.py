"""Rigid bodies lead the world's frame: particles and spring meshes meet them as moving
colliders (boxes and spheres as analytic shapes, hulls as meshes)."""
from __future__ import annotations

import numpy as np

from physanim.core.collision.hull import convex_hull
from physanim.core.particles import (EmitterFrame, EmitterSettings, ParticleDrive, ParticleSolver,
                                     ParticleSystem)
from physanim.core.rigid.mass import polyhedron_mass
from physanim.core.rigid.model import RigidBodySettings
from physanim.core.rigid.solver import RigidBodySystem
from physanim.core.world import World, WorldFrame
from physanim.tests.core.helpers import particle_model, place
from physanim.tests.core.rigid_helpers import DT, G, box, ground, world


def _rain(n=400, seed=0):
    rng = np.random.default_rng(seed)
    x = np.column_stack([rng.uniform(-0.4, 0.4, n), rng.uniform(-0.4, 0.4, n),
                         rng.uniform(2.0, 3.0, n)])
    return x


def _run(rigid_body, frames=48):
    model, solver, state = world(rigid_body)
    pmodel = particle_model(EmitterSettings(name="Rain"))
    pstate = pmodel.state(0.0)
    place(pstate, _rain(), np.zeros((400, 3)))
    systems = [ParticleSystem(ParticleSolver(pmodel, "SYMPLECTIC_EULER", 4), pstate),
               RigidBodySystem(solver, state)]  # listed after the particles: it still leads
    w = World(systems)
    idle = EmitterFrame(active=False)
    for f in range(frames):
        w.advance(WorldFrame(f, f * DT, DT, G, [ground()]), {systems[0]: ParticleDrive([idle])})
    return model, state, pstate


def test_particles_land_on_a_falling_box_not_in_it():
    model, state, pstate = _run(box("Crate", (0.5, 0.5, 0.5), (0.0, 0.0, 1.2)))
    top = state.body_x[0, 2] + 0.5
    assert abs(state.body_x[0, 2] - 0.5) < 0.01  # the crate fell and rests on the ground
    x = pstate.particle_x
    over = (np.abs(x[:, 0]) < 0.45) & (np.abs(x[:, 1]) < 0.45)
    assert over.sum() > 100  # most of the rain is on the crate
    assert np.all(x[over, 2] > top - 1e-3)  # on it, none inside


def test_particles_rest_on_a_convex_hull_body():
    rng = np.random.default_rng(2)
    cloud = rng.normal(size=(30, 3)) * (0.6, 0.6, 0.3)
    hull = convex_hull(cloud)
    rock = RigidBodySettings("Rock", "HULL", polyhedron_mass(hull.points, hull.triangles,
                                                             density=1000.0),
                             hull=hull.points[hull.vertices], position=(0.0, 0.0, 0.6))
    model, state, pstate = _run(rock)
    # every particle is outside the rock's hull at the end
    from physanim.core.rigid import quaternion as quat
    local = quat.rotate(quat.conjugate(state.body_q[:1]), pstate.particle_x - state.body_x[0])
    c = hull.points[hull.vertices].mean(axis=0) - model.body_com[0]
    tri = hull.points[hull.triangles] - model.body_com[0]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1)[:, None]
    n *= np.sign(np.einsum("ij,ij->i", n, tri[:, 0] - c))[:, None]  # outward
    depth = np.einsum("pj,tj->pt", local, n) - np.einsum("tj,tj->t", tri[:, 0], n)
    inside = (depth < -1e-3).all(axis=1)
    assert not inside.any()
