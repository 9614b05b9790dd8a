"""Collider thickness: every shape grows by it, in world units, under any affine transform."""
import math

import numpy as np
import pytest

from physanim.core.contact import ColliderFrame
from physanim.core.particles import (
    EmitterFrame, EmitterSettings, FrameInputs, ParticleModelBuilder, ParticleSolver,
)
from physanim.core.contact import SKIN

DT = 1 / 24


def _drop(collider, start, frames=60, substeps=4):
    builder = ParticleModelBuilder()
    builder.add_emitter(EmitterSettings("Drop"))
    model = builder.finalize()
    state = model.state()
    state.append(0, np.atleast_2d(start), np.zeros((len(np.atleast_2d(start)), 3)),
                 np.ones(len(np.atleast_2d(start))), np.zeros(len(np.atleast_2d(start))),
                 np.full(len(np.atleast_2d(start)), 1e9), np.ones(len(np.atleast_2d(start))))
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps)
    for f in range(frames):
        solver.advance(state, FrameInputs(f, f * DT, DT, emitters=[EmitterFrame(active=False)],
                                          colliders=[collider]))
    return state


@pytest.mark.parametrize("scale_z", [1.0, 3.0])
def test_particle_rests_thickness_above_a_scaled_ground(scale_z):
    # Scaling the ground's local z must not change the world-space thickness.
    m = np.diag([2.0, 2.0, scale_z, 1.0])
    m[2, 3] = 0.5
    ground = ColliderFrame("Ground", "HALF_SPACE", m, m, restitution=0.0, friction=0.5,
                           thickness=0.05)
    state = _drop(ground, [0.0, 0.0, 1.0])
    assert state.particle_x[0, 2] == pytest.approx(0.55, abs=2 * SKIN)
    assert abs(state.particle_v[0, 2]) < 1e-9


def test_points_stay_thickness_outside_a_sphere():
    radius, thickness = 0.7, 0.03
    m = np.diag([radius, radius, radius, 1.0])
    ball = ColliderFrame("Ball", "SPHERE", m, m, restitution=0.0, friction=0.0,
                         thickness=thickness)
    rng = np.random.default_rng(4)
    start = np.column_stack([rng.uniform(-0.5, 0.5, (50, 2)), np.full(50, 2.0)])
    state = _drop(ball, start, frames=40)
    r = np.linalg.norm(state.particle_x, axis=1)
    assert r.min() >= radius + thickness - 1e-6


def test_thick_box_and_plane_push_points_to_their_grown_faces():
    box = ColliderFrame("Box", "BOX", np.eye(4), np.eye(4), restitution=0.0, friction=1.0,
                        thickness=0.1)
    state = _drop(box, [[0.2, 0.1, 3.0]])
    assert state.particle_x[0, 2] == pytest.approx(1.1, abs=2 * SKIN)
    plane = ColliderFrame("Sheet", "PLANE", np.eye(4), np.eye(4), restitution=0.0, friction=1.0,
                          thickness=0.02)
    state = _drop(plane, [[0.3, -0.4, 1.0]])
    assert state.particle_x[0, 2] == pytest.approx(0.02, abs=2 * SKIN)


def test_negative_thickness_is_rejected():
    with pytest.raises(ValueError, match="thickness must be >= 0"):
        ColliderFrame("G", "HALF_SPACE", np.eye(4), np.eye(4), thickness=-0.1)
    assert math.isfinite(SKIN)


@pytest.mark.parametrize("restitution, friction, message", [
    (-0.5, math.inf, r"friction must be finite \(got inf\)"),  # the non-finite one first
    (math.nan, -1.0, r"restitution must be finite \(got nan\)"),
    (0.5, -1.0, r"friction must be >= 0 \(got -1.0\)"),
    (-0.5, -1.0, r"restitution must be >= 0 \(got -0.5\)"),
])
def test_bad_values_are_named_non_finite_first(restitution, friction, message):
    with pytest.raises(ValueError, match=message):
        ColliderFrame("G", "HALF_SPACE", np.eye(4), np.eye(4), restitution=restitution,
                      friction=friction)
