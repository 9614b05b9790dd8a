"""Large particle states moved in blocks (:mod:`physanim.core.particles.blocks`): where every
particle's sub-step is its own, moving the state block by block gives the same particles to the
bit as moving it whole (RK4 to rounding), with the same reports; where particles act on each
other it is not split. The block is made small here (200 particles) so that a few thousand
particles span many blocks."""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.contact import ColliderFrame
from physanim.core.errors import PhysanimError
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


def _flight(n: int, bad: dict, life: float = 1e9, emitter=None):
    """``n`` particles in flight above a ground, moved in blocks of 200 (symplectic Euler, one
    sub-step); ``bad``: {row: (x, v)} set on particles; one frame advanced. Returns the
    error it raised (or None) and the state."""
    model = particle_model(EmitterSettings(name="Grains"))
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", 1)
    state = model.state(0.0)
    rng = np.random.default_rng(5)
    x = rng.uniform(-5.0, 5.0, (n, 3)) + [0.0, 0.0, 20.0]
    v = rng.normal(0.0, 1.0, (n, 3))
    lives = np.full(n, 1e9)
    lives[: n // 4] = life  # the first quarter dies within the first sub-step when life is short
    state.append(0, x, v, np.full(n, 0.1), np.zeros(n), lives, np.full(n, 0.05))
    for row, (xi, vi) in bad.items():
        state.particle_x[row], state.particle_v[row] = xi, vi
    try:
        solver.advance(state, FrameInputs(frame=7, t0=0.0, frame_dt=DT,
                                          emitters=[emitter or EmitterFrame(active=False)],
                                          colliders=[GROUND]))
    except PhysanimError as exc:
        return exc, state
    return None, state


@pytest.mark.parametrize("row, x, v, words", [
    (1450, (0.0, 0.0, 20.0), (2e5, 0.0, 0.0), "speed"),  # block 8 of 10: beyond the speed limit
    (610, (0.0, 0.0, 20.0), (np.nan, 0.0, 0.0), "velocity became"),  # block 4: a blow-up
    (1999, (3e5, 0.0, 20.0), (0.0, 0.0, 0.0), "world bound"),  # the last block's last row
])
def test_a_particle_out_of_bounds_in_any_block_is_named(monkeypatch, row, x, v, words):
    """The bounds are checked block by block as the blocks are moved (in the cache): a particle
    beyond them in any block stops the frame naming it, as the whole state's check did."""
    monkeypatch.setattr(blocks, "BLOCK", 200)
    exc, state = _flight(2000, {row: (x, v)})
    assert exc is not None and words in str(exc), exc
    assert f"particle {row}" in str(exc) and "frame 7" in str(exc) and "Grains" in str(exc)


def test_newborns_out_of_bounds_are_named_after_the_moved_were_checked(monkeypatch):
    """Where every moved block was within the bounds, the check that follows the births covers
    the newborn (after the deaths of the same sub-step): a birth faster than the speed limit
    stops the frame naming it, with more particles dying than are born."""
    monkeypatch.setattr(blocks, "BLOCK", 200)
    fast = EmitterFrame(rate=20.0, speed=2e5, lifetime=10.0, mass=0.1, size=0.02)
    exc, state = _flight(2000, {}, life=0.01, emitter=fast)
    assert exc is not None and "speed" in str(exc) and "beyond the speed limit" in str(exc), exc
    born = int(str(exc).split("particle ")[1].split()[0])
    assert born >= 2000  # a newborn's id (the placed ones are 0..1999)
    exc, state = _flight(2000, {}, life=0.01)  # the same deaths, nobody born: no error
    assert exc is None and state.particle_count == 1500
