"""Large particle states moved in blocks (:mod:`physanim.core.particles.blocks`): where every
particle's sub-step is its own, moving the state block by block gives the same particles to the
bit as moving it whole (RK4 to rounding), with the same reports; where particles act on each
other it is not split. The block is made small here (200 particles) so that a few thousand
particles span many blocks."""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.contact import ColliderFrame
from physanim.core.forces import Wind
from physanim.core.particles import EmitterFrame, EmitterSettings, FrameInputs, ParticleSolver
from physanim.core.particles import blocks
from physanim.core.particles.pair_collisions import ParticleCollisions
from physanim.tests.core.helpers import particle_model, translation

DT = 1.0 / 24.0
GROUND = ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4), restitution=0.3,
                       friction=0.6)
BOX = ColliderFrame("Box", "BOX", translation(-0.5, 0.0, 0.25) @ np.diag([0.5, 0.5, 0.25, 1.0]),
                    translation(-0.5, 0.0, 0.25) @ np.diag([0.5, 0.5, 0.25, 1.0]))
SQUARE = np.array([[-2.0, -1.0, 0.0], [2.0, -1.0, 0.0], [-2.0, 1.0, 0.0], [2.0, 1.0, 0.0]])
WIND = Wind("Gust", (1.0, 0.0, 0.0), 2.0, noise=1.0, seed=2)


def _run(monkeypatch, block: int, integrator: str, collisions=(), frames: int = 30):
    """Every frame's (ids, x, v, report) of grains sprayed onto a ground and a box in a gusty
    wind, moved in blocks of ``block`` particles, and how many sub-steps were split."""
    monkeypatch.setattr(blocks, "BLOCK", block)
    split = []
    move = blocks.in_blocks

    def counted(m, step, state, *args):
        split.append(step.blocks and state.particle_count >= 2 * blocks.BLOCK)
        return move(m, step, state, *args)
    monkeypatch.setattr("physanim.core.particles.solver.in_blocks", counted)
    model = particle_model(EmitterSettings(name="Grains", source="FACES", direction="NORMAL",
                                           triangles=np.array([[0, 1, 3], [0, 3, 2]]),
                                           vertex_count=4), seed=3)
    solver = ParticleSolver(model, integrator, 2)
    state = model.state(DT)
    m = translation(0.0, 0.0, 1.0)
    out = []
    for frame in range(1, frames + 1):
        emitter = EmitterFrame(rate=300.0, speed=2.0, spread=0.6, lifetime=20.0, mass=0.1,
                               size=0.02, active=frame < 12, matrix0=m, matrix1=m.copy(),
                               verts0=SQUARE, verts1=SQUARE)
        report = solver.advance(state, FrameInputs(
            frame=frame, t0=frame * DT, frame_dt=DT, emitters=[emitter],
            colliders=[GROUND, BOX], forces=[WIND], collisions=list(collisions)))
        out.append((state.particle_id.copy(), state.particle_x.copy(), state.particle_v.copy(),
                    report))
    monkeypatch.undo()
    return out, sum(split)


@pytest.mark.parametrize("integrator", ["SYMPLECTIC_EULER", "EULER", "MIDPOINT", "RK4"])
def test_blocks_move_the_particles_as_the_whole_state_does(monkeypatch, integrator):
    whole, none = _run(monkeypatch, 10 ** 9, integrator)
    split, count = _run(monkeypatch, 200, integrator)
    assert none == 0 and count > 20  # (3,000 particles at most: up to 15 blocks)
    assert whole[-1][3].alive > 2000 and sum(r[3].collisions for r in whole) > 1000
    exact = integrator != "RK4"  # RK4 sums its stages over the whole state in one product
    for frame, (a, b) in enumerate(zip(split, whole), start=1):
        assert np.array_equal(a[0], b[0]), frame
        for u, w in zip(a[1:3], b[1:3]):
            if exact:
                assert np.array_equal(u, w), frame
            else:
                np.testing.assert_allclose(u, w, rtol=0, atol=1e-12)
        assert (a[3].births, a[3].deaths, a[3].integrator_steps, a[3].alive) == \
            (b[3].births, b[3].deaths, b[3].integrator_steps, b[3].alive), frame
        if exact:
            assert a[3].collisions == b[3].collisions, frame


def test_particles_that_collide_with_each_other_are_not_split(monkeypatch):
    out, count = _run(monkeypatch, 200, "SYMPLECTIC_EULER", [ParticleCollisions("Grains")], 8)
    assert out[-1][3].alive > 2000 and count == 0
