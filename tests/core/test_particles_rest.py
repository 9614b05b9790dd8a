"""Particles at rest (:mod:`physanim.core.particles.rest`): a particle the last sub-step left
exactly as it was is skipped while the sub-step stays the same function, and nothing about the
results changes — every frame is compared, bit for bit, with the same scene computed in full
(the skipping switched off). Scenes settle on still colliders, then something wakes them."""
from __future__ import annotations

import pickle

import numpy as np
import pytest

from physanim.core.contact import ColliderFrame
from physanim.core.forces import Wind
from physanim.core.particles import EmitterFrame, EmitterSettings, FrameInputs, ParticleSolver
from physanim.core.particles import solver as solver_module
from physanim.core.particles.settings import SpringLink
from physanim.tests.core.helpers import particle_model, rotation, translation

DT = 1.0 / 24.0
GROUND = ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4), restitution=0.3,
                       friction=0.6)
# a 4 x 4 m bounded plane at z = 0.2 and a box, beside the ground
SHELF = ColliderFrame("Shelf", "PLANE", translation(2.5, 0.0, 0.2) @ np.diag([2.0, 2.0, 1.0, 1.0]),
                      translation(2.5, 0.0, 0.2) @ np.diag([2.0, 2.0, 1.0, 1.0]), friction=0.4)
BOX = ColliderFrame("Box", "BOX", translation(-1.5, 0.0, 0.25) @ np.diag([0.5, 0.5, 0.25, 1.0]),
                    translation(-1.5, 0.0, 0.25) @ np.diag([0.5, 0.5, 0.25, 1.0]))
SQUARE = np.array([[-3.0, -1.0, 0.0], [3.0, -1.0, 0.0], [-3.0, 1.0, 0.0], [3.0, 1.0, 0.0]])


def _emitter(frame: int, speed=1.0, spread=0.6, births_until=12, lifetime=8.0) -> EmitterFrame:
    m = translation(0.0, 0.0, 1.0)
    return EmitterFrame(rate=300.0, speed=speed, spread=spread, lifetime=lifetime,
                        lifetime_random=0.3 * lifetime,
                        mass=0.1, size=0.02, active=frame < births_until, matrix0=m,
                        matrix1=m.copy(), verts0=SQUARE, verts1=SQUARE)


def _run(monkeypatch, frames: int, inputs_of, integrator="SYMPLECTIC_EULER", substeps=2,
         skip=True):
    """Every frame's (ids, x, v, report) of the scene ``inputs_of(frame)`` gives."""
    if not skip:
        monkeypatch.setattr(solver_module, "conditions", lambda *args: None)
    model = particle_model(EmitterSettings(name="Grains", source="FACES", direction="NORMAL",
                                           triangles=np.array([[0, 1, 3], [0, 3, 2]]),
                                           vertex_count=4), seed=3)
    solver = ParticleSolver(model, integrator, substeps)
    state = model.state(DT)
    out = []
    for frame in range(1, frames + 1):
        report = solver.advance(state, inputs_of(frame))
        out.append((state.particle_id.copy(), state.particle_x.copy(), state.particle_v.copy(),
                    report))
    monkeypatch.undo()
    return out


def _same(skipped, full) -> None:
    for frame, (a, b) in enumerate(zip(skipped, full), start=1):
        for name, u, w in zip(("ids", "positions", "velocities"), a[:3], b[:3]):
            assert np.array_equal(u, w), f"{name} differ at frame {frame}"
        assert (a[3].births, a[3].deaths, a[3].integrator_steps, a[3].alive) == \
            (b[3].births, b[3].deaths, b[3].integrator_steps, b[3].alive)
        # a grain at rest in the corner between the ground and a box's side rests on the side,
        # so gravity takes it into the ground every sub-step and the ground puts it back where
        # it was: a collision the full computation counts and the skipped one does not
        assert a[3].collisions <= b[3].collisions


def _inputs(colliders=(GROUND, SHELF, BOX), gravity=(0.0, 0.0, -9.81), forces=(), **emitter):
    def inputs_of(frame):
        g = gravity(frame) if callable(gravity) else gravity
        return FrameInputs(frame=frame, t0=frame * DT, frame_dt=DT, gravity=g,
                           emitters=[_emitter(frame, **emitter)],
                           colliders=list(colliders(frame) if callable(colliders) else colliders),
                           forces=list(forces(frame) if callable(forces) else forces))
    return inputs_of


@pytest.mark.parametrize("integrator", ["SYMPLECTIC_EULER", "MIDPOINT"])
def test_a_settled_pile_is_skipped_and_ends_as_computed_in_full(monkeypatch, integrator):
    """Grains sprayed onto a ground, a shelf and a box slide, bounce and stop; most end at rest
    (and die of old age meanwhile) — the same bits as the scene computed in full."""
    inputs_of = _inputs(lifetime=2.2)
    skipped = _run(monkeypatch, 60, inputs_of, integrator)
    full = _run(monkeypatch, 60, inputs_of, integrator, skip=False)
    _same(skipped, full)
    alive = skipped[-1][3].alive
    assert alive > 500 and skipped[-1][3].at_rest > 0.9 * alive
    assert all(r[3].at_rest == 0 for r in full)
    assert sum(r[3].deaths for r in skipped) > 1000  # at rest or not, they die on time


def test_at_the_defaults_grains_on_the_ground_rest():
    """A default emitter over a ground (nothing else set): once they stop bouncing they rest."""
    model = particle_model(EmitterSettings(name="Emitter"))
    solver = ParticleSolver(model)
    state = model.state(0.0)
    for frame in range(1, 97):
        report = solver.advance(state, FrameInputs(
            frame=frame, t0=frame * DT, frame_dt=DT, emitters=[EmitterFrame(
                matrix0=translation(0, 0, 1), matrix1=translation(0, 0, 1), lifetime=10.0)],
            colliders=[ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4))]))
    assert report.alive > 0 and report.at_rest > 0.5 * report.alive
    rest = np.flatnonzero(np.all(state.particle_v == 0.0, axis=1))
    assert len(rest) >= report.at_rest and np.all(state.particle_x[rest, 2] < 0.01)


def _wakes(frame_changed, **scene):
    def inputs_of(frame):
        return _inputs(**{k: (v(frame >= frame_changed) if callable(v) else v)
                          for k, v in scene.items()})(frame)
    return inputs_of


@pytest.mark.parametrize("change", ["gravity", "ground moves", "friction keyed", "wind",
                                    "shelf tilts"])
def test_what_could_move_particles_at_rest_wakes_them(monkeypatch, change):
    """The pile settles for 40 frames, then something changes; the particles respond exactly as
    the full computation's (and, where the change moves them, they do move)."""
    lifted = translation(0.0, 0.0, 0.05)
    tilted = translation(2.5, 0.0, 0.2) @ rotation((1.0, 0.0, 0.0), 0.6) @ \
        np.diag([2.0, 2.0, 1.0, 1.0])
    scene = {
        "gravity": dict(gravity=lambda on: (0.0, 0.0, 3.0) if on else (0.0, 0.0, -9.81)),
        "ground moves": dict(colliders=lambda on: (ColliderFrame(
            "Ground", "HALF_SPACE", lifted if on else np.eye(4), lifted if on else np.eye(4),
            restitution=0.3, friction=0.6), SHELF, BOX)),
        "friction keyed": dict(gravity=(2.0, 0.0, -9.81), colliders=lambda on: (ColliderFrame(
            "Ground", "HALF_SPACE", np.eye(4), np.eye(4), restitution=0.3,
            friction=0.05 if on else 0.6), SHELF, BOX)),
        "wind": dict(forces=lambda on: (Wind("Wind", (1.0, 0.0, 0.0), 0.5),) if on else ()),
        "shelf tilts": dict(colliders=lambda on: (GROUND, ColliderFrame(
            "Shelf", "PLANE", tilted if on else SHELF.matrix0, tilted if on else SHELF.matrix0,
            friction=0.4), BOX)),
    }[change]
    inputs_of = _wakes(40, **scene)
    skipped = _run(monkeypatch, 46, inputs_of)
    full = _run(monkeypatch, 46, inputs_of, skip=False)
    _same(skipped, full)
    assert skipped[38][3].at_rest > 0.8 * skipped[38][3].alive
    ids0, x0 = skipped[38][0], skipped[38][1]
    ids1, x1 = skipped[-1][0], skipped[-1][1]
    both = np.isin(ids1, ids0)
    moved = np.any(x1[both] != x0[np.isin(ids0, ids1)], axis=1).sum()
    assert moved > 0.1 * len(ids1)


TURNED = translation(1.8, 0.0, 0.5) @ rotation((1.0, 2.0, 3.0), 0.7) @ np.diag([0.47, 0.47, 0.47, 1.0])


@pytest.mark.parametrize("shape", ["SPHERE", "BOX"])
def test_one_grain_moving_among_grains_at_rest_near_a_turned_collider(monkeypatch, shape):
    """The grains lying still are skipped while one slides down a turned sphere or box: that
    one is then mapped into the collider's frame alone, and must get the bits it gets among
    the others (BLAS rounds a single row unlike several: ``transform_points`` maps one row as
    a row of two)."""
    collider = ColliderFrame("Ball", shape, TURNED, TURNED, restitution=0.0, friction=0.05)

    def inputs_of(frame):
        return FrameInputs(frame=frame, t0=frame * DT, frame_dt=DT, colliders=[GROUND, collider],
                           emitters=[EmitterFrame(active=False)])

    def run(skip):
        if not skip:
            monkeypatch.setattr(solver_module, "conditions", lambda *args: None)
        model = particle_model(EmitterSettings(name="Grains"), seed=1)
        solver = ParticleSolver(model, "SYMPLECTIC_EULER", 4)
        state = model.state(0.0)
        x = np.array([[0.0, 0.0, 1e-4], [0.2, 0.0, 1e-4], [0.4, 0.0, 1e-4],
                      [1.8234567, 0.0156789, 0.98]])
        state.append(0, x, np.zeros_like(x), np.full(4, 0.1), np.zeros(4), np.full(4, 1e9),
                     np.full(4, 0.02))
        out = [(state.particle_id.copy(), state.particle_x.copy(), state.particle_v.copy(),
                solver.advance(state, inputs_of(frame))) for frame in range(1, 25)]
        monkeypatch.undo()
        return out

    skipped, full = run(True), run(False)
    _same(skipped, full)
    assert skipped[-1][3].at_rest >= 3
    assert np.abs(skipped[-1][1][3] - skipped[0][1][3]).max() > 0.01  # the grain slid


def test_springs_born_during_a_frame_and_rk4_skip_nothing(monkeypatch):
    """An emitter that joins its particles by springs (the first ones born mid-frame) and RK4
    (whose stages are summed by one BLAS product over the whole state) are not particle by
    particle: nothing is skipped there, and the results are the full computation's."""
    def run(settings, integrator, skip):
        if not skip:
            monkeypatch.setattr(solver_module, "conditions", lambda *args: None)
        model = particle_model(settings, seed=1)
        solver = ParticleSolver(model, integrator, 8)
        state = model.state(0.0)
        out = []
        for frame in range(1, 6):
            m0, m1 = translation(0.2 * (frame - 1)), translation(0.2 * frame)
            report = solver.advance(state, FrameInputs(
                frame=frame, t0=(frame - 1) * DT, frame_dt=DT, gravity=(0.0, 0.0, 0.0),
                emitters=[EmitterFrame(rate=6.0, speed=0.0, lifetime=100.0, mass=0.1,
                                       matrix0=m0, matrix1=m1)]))
            out.append((state.particle_id.copy(), state.particle_x.copy(),
                        state.particle_v.copy(), report))
        monkeypatch.undo()
        return out

    chain = EmitterSettings(name="Chain", link=SpringLink(200.0, 0.5, rest_length=0.05))
    for settings, integrator in ((chain, "SYMPLECTIC_EULER"),
                                 (EmitterSettings(name="Still"), "RK4")):
        skipped = run(settings, integrator, True)
        _same(skipped, run(settings, integrator, False))
        assert all(r[3].at_rest == 0 for r in skipped)
    # still particles without springs or RK4 do rest
    assert run(EmitterSettings(name="Still"), "SYMPLECTIC_EULER", True)[-1][3].at_rest > 0


def test_a_solver_saved_before_particles_rested_resumes():
    """A bake checkpoint (the pickled solver) from before this optimisation has no record of
    particles at rest: it resumes with none."""
    model = particle_model(EmitterSettings(name="Grains"))
    solver = ParticleSolver(model)
    del solver.__dict__["_rest"]
    resumed = pickle.loads(pickle.dumps(solver))
    state = model.state(0.0)
    report = resumed.advance(state, _inputs()(1))
    assert report.alive > 0 and resumed.at_rest == 0


def test_the_still_test_is_rows_whose_every_position_and_velocity_stayed():
    """:func:`~physanim.core.particles.rest.unchanged` (velocities first, stopping once no row
    is left) against the plain definition, on rows that differ in any one column or none."""
    from physanim.core.particles.rest import unchanged

    rng = np.random.default_rng(7)
    for moved in (0, 1, 5, 40):
        x0, v0 = rng.normal(size=(40, 3)), rng.normal(size=(40, 3))
        x1, v1 = x0.copy(), v0.copy()
        rows = rng.choice(40, moved, replace=False)
        cols = rng.integers(0, 6, moved)
        for r, c in zip(rows, cols):
            (x1 if c < 3 else v1)[r, c % 3] += 1e-12
        expected = (x1 == x0).all(axis=1) & (v1 == v0).all(axis=1)
        assert np.array_equal(unchanged(x0, v0, x1, v1), expected)
        assert unchanged(x0, v0, x1, v1).sum() == 40 - moved
    empty = np.zeros((0, 3))
    assert unchanged(empty, empty, empty, empty).shape == (0,)
