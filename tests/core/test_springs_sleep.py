"""Spring meshes at rest sleep (:mod:`physanim.core.springs.sleep`): a cloth that has settled
stops being stepped, lies where an unsleeping one lies, and wakes when anything around it
changes; one that still moves, slowly, never sleeps."""
from __future__ import annotations

import pickle

import numpy as np
import pytest

from physanim.core.contact import ColliderFrame
from physanim.core.forces import Drag, Wind
from physanim.core.springs import (SpringFrameInputs, SpringMeshBuilder, SpringMeshSettings,
                                   SpringMeshSolver, VirtualSprings)
from physanim.core.springs.model import Attachment
from physanim.core.springs import sleep
from physanim.tests.core.helpers import grid as _grid

DT = 1.0 / 24.0
GROUND = ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4))


def _sheet(sleeps: bool = True, pins=None, size: float = 1.0, height: float = 0.3,
           hanging: bool = False, virtual=(), attachments=()):
    """A size x size cloth (9 x 9 vertices) ``height`` above the ground, at the defaults
    (``hanging``: upright, its last row on top; ``virtual``: virtual spring groups)."""
    x, edges, tris, ls, lt, lv = _grid(9, 9, size)
    x = x - [0.5 * size, 0.5 * size, -height]
    if hanging:
        x = x[:, [0, 2, 1]] + [0.0, -height, height + 0.5 * size]
    settings = SpringMeshSettings("Sheet") if sleeps else SpringMeshSettings("Sheet", sleep=False)
    builder = SpringMeshBuilder(settings, x, edges, tris, ls, lt, lv, pins)
    for group in virtual:
        builder.add_virtual(group)
    for attachment in attachments:
        builder.add_attachment(attachment)
    return builder.finalize(1)


class _Counted:
    """Counts the integrator's steps (the work a sleeping mesh skips)."""

    def __init__(self, solver: SpringMeshSolver):
        self.steps = 0
        step = solver.integrator.step

        def counted(*args, **kwargs):
            self.steps += 1
            return step(*args, **kwargs)
        solver.integrator.step = counted


def _inputs(frame: int, **kwargs) -> SpringFrameInputs:
    kwargs.setdefault("colliders", [GROUND])
    return SpringFrameInputs(frame, frame * DT, DT, **kwargs)


def test_a_cloth_at_rest_at_the_defaults_falls_asleep_where_an_unsleeping_one_lies():
    """Nothing set but the spring mesh and the ground: the dropped cloth lands, settles and
    sleeps; its sleeping frames step nothing; at frame 60 it lies where the same cloth with
    sleep off lies (within 0.1 mm)."""
    model, awake_model = _sheet(), _sheet(sleeps=False)
    solver = SpringMeshSolver(model, "IMPLICIT", 2, frame_dt=DT, frame=1)
    other = SpringMeshSolver(awake_model, "IMPLICIT", 2, frame_dt=DT, frame=1)
    counted = _Counted(solver)
    state, reference = model.state(), awake_model.state()
    fell = None
    for frame in range(1, 61):
        before = counted.steps
        solver.advance(state, _inputs(frame))
        other.advance(reference, _inputs(frame))
        assert not other.asleep
        if solver.asleep and fell is None:
            fell = frame
        elif fell is not None:  # asleep through the frame: no step, not a micrometre of motion
            assert solver.asleep and counted.steps == before
    assert fell is not None and fell <= 40  # landed by frame 7, then half a second of rest
    assert np.all(state.v == 0.0)
    assert np.abs(state.x - reference.x).max() < 1e-4
    assert state.x[:, 2].min() >= -1e-6 and state.x[:, 2].max() < 0.01


def _settled(model=None, frames: int = 48, **kwargs):
    model = model or _sheet()
    solver = SpringMeshSolver(model, "IMPLICIT", 2, frame_dt=DT, frame=1)
    state = model.state()
    for frame in range(1, frames + 1):
        solver.advance(state, _inputs(frame, **kwargs))
    assert solver.asleep
    return solver, state


def _lifted(frame):
    m1 = np.eye(4)
    m1[2, 3] = 0.05
    return {"colliders": [ColliderFrame("Ground", "HALF_SPACE", np.eye(4), m1)]}


@pytest.mark.parametrize("change, moved", [
    # the ground keyed to rise 5 cm in a frame: the cloth goes up with it
    (_lifted, lambda x0, x: x[:, 2].min() > 0.04),
    # gravity turned sideways (the ground's friction holds it no more than mu g)
    (lambda f: {"gravity": (9.81, 0.0, -1.0)}, lambda x0, x: (x - x0)[:, 0].mean() > 1e-3),
    # a wind switched on lifts the cloth off the ground
    (lambda f: {"winds": [Wind("Gust", (0.0, 0.0, 1.0), 200.0)]},
     lambda x0, x: x[:, 2].mean() > x0[:, 2].mean() + 1e-3),
], ids=["collider moves", "gravity changes", "wind"])
def test_a_sleeping_cloth_wakes_when_anything_around_it_changes(change, moved):
    solver, state = _settled()
    x0 = state.x.copy()
    counted = _Counted(solver)
    for frame in range(49, 53):
        solver.advance(state, _inputs(frame, **change(frame)))
        assert not solver.asleep
    assert counted.steps == 8
    assert moved(x0, state.x)


def test_a_sleeping_cloth_under_the_same_conditions_stays_asleep_across_a_save():
    """A bake saved and resumed: the solver pickled asleep resumes asleep; one saved before
    meshes slept (no sleep in its state) resumes awake and never sleeps."""
    solver, state = _settled()
    again = pickle.loads(pickle.dumps(solver))
    assert again.asleep
    counted = _Counted(again)
    again.advance(state, _inputs(49))
    assert again.asleep and counted.steps == 0
    old = pickle.loads(pickle.dumps(solver))
    del old.__dict__["_sleep"]
    old = pickle.loads(pickle.dumps(old))
    assert not old.asleep
    counted = _Counted(old)
    for frame in range(49, 73):
        old.advance(state, _inputs(frame))
    assert not old.asleep and counted.steps == 48


def test_pins_that_move_wake_the_mesh_and_still_ones_let_it_sleep():
    """A cloth hanging from two pinned corners comes to rest and sleeps; its pins' targets
    moved by 1 cm (an animated rest shape) wake it and pull it along."""
    weights = np.zeros(81)
    weights[[72, 80]] = 1.0  # the corners of the last row, on top
    model = _sheet(pins=weights, height=1.0, hanging=True)
    solver = SpringMeshSolver(model, "IMPLICIT", 2, frame_dt=DT, frame=1)
    state = model.state()
    rest = model.rest_x
    for frame in range(1, 24 * 12):
        solver.advance(state, _inputs(frame, colliders=[], rest0=rest, rest1=rest))
        if solver.asleep:
            break
    assert solver.asleep, "the hanging cloth never came to rest in 12 s"
    x0 = state.x.copy()
    moved = rest + [0.01, 0.0, 0.0]
    solver.advance(state, _inputs(frame + 1, colliders=[], rest0=rest, rest1=moved))
    assert not solver.asleep
    assert np.allclose(state.x[[72, 80]], moved[[72, 80]])
    assert (state.x - x0)[:, 0].mean() > 1e-4


TOP = np.arange(72, 81)  # the last row: on top of a hanging sheet


def _until_asleep(model, integrator: str = "IMPLICIT", substeps: int = 2,
                  frames: int = 24 * 12, **kwargs):
    """Step ``model`` under the same inputs (``kwargs``, see :func:`_inputs`) until it sleeps;
    the solver, state and the frame it fell asleep in."""
    solver = SpringMeshSolver(model, integrator, substeps, frame_dt=DT, frame=1)
    state = model.state()
    for frame in range(1, frames):
        solver.advance(state, _inputs(frame, **kwargs))
        if solver.asleep:
            return solver, state, frame
    raise AssertionError(f"{integrator}: the cloth never came to rest")


def test_soft_pins_whose_rest_shape_moves_wake_the_mesh():
    """Held by soft pins only (PIN virtual springs, no hard pin): the animated rest shape
    moving 1 cm under them wakes the sleeping mesh, and the springs pull it along."""
    soft = VirtualSprings("PIN", TOP, np.full(len(TOP), 0.5), 0.0, 2000.0, 20.0)
    model = _sheet(height=1.0, hanging=True, virtual=[soft])
    solver, state, frame = _until_asleep(model, colliders=[])
    x0 = state.x.copy()
    rest = model.rest_x
    step = np.array([1e-3, 0.0, 0.0])
    for k in range(1, 13):
        solver.advance(state, _inputs(frame + k, colliders=[], rest0=rest + (k - 1) * step,
                                      rest1=rest + k * step))
        assert not solver.asleep
    assert (state.x - x0)[TOP, 0].mean() > 5e-3


def test_attached_vertices_wake_the_mesh_when_their_target_moves():
    """An ATTACH group on a still hook sleeps with the cloth; the hook keyed to move wakes it
    and carries the attached row along."""
    hook = np.eye(4)
    attach = VirtualSprings("ATTACH", TOP, np.ones(len(TOP)), 0.0, 5000.0, 20.0, target="Hook")
    model = _sheet(height=1.0, hanging=True, virtual=[attach])
    solver, state, frame = _until_asleep(model, colliders=[], targets={"Hook": (hook, hook)})
    moved = hook.copy()
    moved[0, 3] = 0.02
    x0 = state.x.copy()
    solver.advance(state, _inputs(frame + 1, colliders=[], targets={"Hook": (hook, moved)}))
    assert not solver.asleep
    for k in range(2, 13):
        solver.advance(state, _inputs(frame + k, colliders=[], targets={"Hook": (moved, moved)}))
    assert (state.x - x0)[TOP, 0].mean() > 0.01


def test_a_mesh_sewn_onto_a_collider_wakes_when_the_collider_moves():
    """An attachment to a collider it does not collide with (a cloth sewn onto a box, passing
    through it): the mesh meets no path of that collider, yet the box keyed to move wakes it
    and carries the sewn row."""
    box = np.diag([0.1, 0.1, 0.1, 1.0])
    box[:3, 3] = [0.0, 0.0, 2.0]
    model = _sheet(height=1.0, hanging=True, attachments=[Attachment(TOP, "Box", collide=False)])
    solver, state, frame = _until_asleep(model, colliders=[ColliderFrame("Box", "BOX", box,
                                                                         box)])
    x0 = state.x.copy()
    moved = box.copy()
    moved[0, 3] = 0.02
    solver.advance(state, _inputs(frame + 1, colliders=[ColliderFrame("Box", "BOX", box, moved)]))
    assert not solver.asleep
    assert np.allclose((state.x - x0)[TOP, 0], 0.02)


def test_a_moving_collider_or_a_gusting_wind_keeps_a_still_mesh_awake():
    """Anything that moves among the colliders (a ball swinging far from the cloth, the same
    frame over and over), or a wind with gusts (they change with time, however weak), keeps
    the mesh awake: the sub-step is not known to be the same function."""
    far = np.eye(4)
    far[:3, 3] = [10.0, 0.0, 1.0]
    near = far.copy()
    near[1, 3] = 0.5
    ball = ColliderFrame("Ball", "SPHERE", far, near)
    gusts = Wind("Gusts", (0.0, 0.0, -1.0), 0.01, noise=0.5)
    for extra in ({"colliders": [GROUND, ball]}, {"winds": [gusts]}):
        model = _sheet()
        solver = SpringMeshSolver(model, "IMPLICIT", 2, frame_dt=DT, frame=1)
        state = model.state()
        for frame in range(1, 61):
            solver.advance(state, _inputs(frame, **extra))
            assert not solver.asleep, (extra, frame)
        assert np.abs(state.v).max() < 1e-3  # at rest all the same


def test_steady_forces_let_a_mesh_sleep_and_a_change_of_them_wakes_it():
    """Air drag, and a steady wind pressing the cloth onto the ground, push a still cloth the
    same way every frame: it sleeps under them; the wind keyed stronger wakes it."""
    drag, wind = Drag("Air", 0.1, 0.01), Wind("Down", (0.0, 0.0, -1.0), 5.0)
    solver, state = _settled(fields=[drag], winds=[wind])
    counted = _Counted(solver)
    solver.advance(state, _inputs(49, fields=[Drag("Air", 0.1, 0.01)], winds=[wind]))
    assert solver.asleep and counted.steps == 0  # equal values: the same force
    solver.advance(state, _inputs(50, fields=[drag], winds=[Wind("Down", (0.0, 0.0, -1.0), 6.0)]))
    assert not solver.asleep and counted.steps == 2


@pytest.mark.parametrize("integrator", ["BDF2", "SYMPLECTIC_EULER"])
def test_other_integrators_sleep_and_wake(integrator):
    """Implicit BDF2 and an explicit integrator (at substeps it can take) sleep as implicit
    Euler does, and a sideways gravity wakes them."""
    substeps = 2 if integrator == "BDF2" else 200
    solver, state, frame = _until_asleep(_sheet(), integrator, substeps, frames=73)
    x0 = state.x.copy()
    for k in range(1, 7):
        solver.advance(state, _inputs(frame + k, gravity=(9.81, 0.0, -1.0)))
        assert not solver.asleep
    assert (state.x - x0)[:, 0].mean() > 1e-3


@pytest.mark.parametrize("mu", [0.2, 0.5])
def test_a_cloth_sliding_down_a_slope_never_sleeps(mu):
    """Slopes of 30 degrees, friction below tan 30 = 0.577: the cloth accelerates at
    g (sin - mu cos), 0.24 m/s^2 at mu 0.5 — from rest, slower than the sleep speed only in
    its first frame."""
    c, s = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
    m = np.eye(4)
    m[1:3, 1:3] = [[c, -s], [s, c]]
    slope = ColliderFrame("Slope", "HALF_SPACE", m, m, restitution=0.0, friction=mu)
    x, edges, tris, ls, lt, lv = _grid(7, 7, 0.4)
    x = (x - [0.2, 0.2, 0.0]) @ m[:3, :3].T
    model = SpringMeshBuilder(SpringMeshSettings("Patch"), x, edges, tris, ls, lt,
                              lv).finalize(1)
    solver = SpringMeshSolver(model, "IMPLICIT", 2, frame_dt=DT, frame=1)
    state = model.state()
    for frame in range(1, 49):
        solver.advance(state, _inputs(frame, colliders=[slope]))
        assert not solver.asleep, frame


def test_the_sleep_speed_is_a_share_of_the_mesh_size_up_to_a_limit():
    """A 2 cm napkin sleeps below 0.03 mm/s (a thousandth of its size per second), a 10 m sail
    below 2 mm/s: a slow creep of a small mesh is not taken for rest."""
    x, *_ = _grid(3, 3, 1.0)
    diagonal = np.sqrt(2.0)
    assert sleep.Sleep.for_mesh(0.02 * x).speed == pytest.approx(0.02 * diagonal * 1e-3)
    assert sleep.Sleep.for_mesh(10.0 * x).speed == sleep.SLEEP_SPEED


class _Path:
    """Four vertices moving together along x(t) (a function of the time [s]), frame by frame
    into a :class:`sleep.Sleep`."""

    def __init__(self, keeper, where, dt: float = DT):
        self.keeper, self.where, self.t, self.dt = keeper, where, 0.0, dt

    def frame(self, now, where=None) -> bool:
        """One frame interval under ``now``; whether the mesh fell asleep at its end."""
        where = where or self.where
        x0, x1 = where(self.t), where(self.t + self.dt)
        v1 = (where(self.t + self.dt + 1e-6) - x1) / 1e-6
        self.t += self.dt
        tile = lambda a: np.tile([a, 0.0, 0.0], (4, 1))  # noqa: E731
        return self.keeper.settle(now, np.ones(4, bool), tile(x0), tile(x1), tile(v1), self.dt)


def _conditions():
    model = _sheet()
    solver = SpringMeshSolver(model, "IMPLICIT", 2, frame_dt=DT, frame=1)
    solver.advance(model.state(), _inputs(1))
    other = sleep.conditions("IMPLICIT", 0.5 * DT, _inputs(2, gravity=(0.0, 0.0, -9.0)),
                             [], np.zeros(81, bool), model.rest_x, model.rest_x, False)
    now = solver._sleep.conditions
    assert now is not None and other is not None and not now.same_as(other)
    return now, other


SWAY_SPEED = 1.01 * sleep.SWAY * 1e-3  # just faster than a sway (for a sleep speed of 1 mm/s)


def test_sleep_takes_half_a_second_of_slow_frames_under_the_same_conditions():
    """A creep at half the sleep speed sleeps after SLEEP_TIME of frames (twelve of 1/24 s):
    it strays less than the sleep speed times SLEEP_TIME from where they began; a frame faster
    than SWAY x the sleep speed (within that distance), or under other conditions, starts the
    count again; the sleeper wakes under other conditions."""
    now, other = _conditions()
    keeper = sleep.Sleep(1e-3)
    creep = _Path(keeper, lambda t: 0.5e-3 * t)
    assert not any(creep.frame(now) for _ in range(11))
    jump = creep.t
    assert not creep.frame(now, lambda t: 0.5e-3 * t + (SWAY_SPEED * (t - jump) if t > jump
                                                         else 0.0))  # one fast frame
    creep.where = lambda t: 0.5e-3 * t + SWAY_SPEED * DT
    assert [creep.frame(now) for _ in range(12)] == [False] * 11 + [True]
    assert keeper.sleeps(now) and keeper.asleep
    assert not keeper.sleeps(other) and not keeper.asleep
    assert not keeper.sleeps(now)  # woken: it must be slow for half a second again
    assert not creep.frame(other)  # other conditions: again
    assert [creep.frame(now) for _ in range(12)] == [False] * 11 + [True]


@pytest.mark.parametrize("fps", [24.0, 25.0, 29.97, 7.0])
def test_a_creep_just_slower_than_the_sleep_speed_sleeps_at_any_frame_rate(fps):
    """At 0.99 x the sleep speed a creep strays 0.99 x the sleep speed times the time its slow
    frames take: asleep after the whole frames that reach SLEEP_TIME (13 at 25 fps, 0.52 s)."""
    now, _ = _conditions()
    frames = int(np.ceil(sleep.SLEEP_TIME * fps - 1e-9))
    creep = _Path(sleep.Sleep(1e-3), lambda t: 0.99e-3 * t, 1.0 / fps)
    assert [creep.frame(now) for _ in range(frames)] == [False] * (frames - 1) + [True]


@pytest.mark.parametrize("speed", [1.1e-3, 2.0e-3])
def test_a_creep_faster_than_the_sleep_speed_never_sleeps(speed):
    """Every frame slower than SWAY x the sleep speed, but the vertices stray further than
    the sleep speed times SLEEP_TIME within every half second: awake for 10 s."""
    now, _ = _conditions()
    creep = _Path(sleep.Sleep(1e-3), lambda t: speed * t)
    assert not any(creep.frame(now) for _ in range(240))


def test_a_sway_about_where_the_mesh_lies_sleeps_and_a_fast_buzz_does_not():
    """A 2 Hz sway of 0.2 mm (peaks of 2.5 mm/s: faster than the sleep speed, 1 mm/s, at
    every pass) stays within 0.5 mm of where it began: asleep after half a second. A buzz of
    0.01 mm at 70 Hz (4.4 mm/s: faster than SWAY x the sleep speed) never sleeps, though it
    strays less."""
    now, _ = _conditions()
    sway = _Path(sleep.Sleep(1e-3), lambda t: 2e-4 * np.sin(2.0 * np.pi * 2.0 * t))
    assert [sway.frame(now) for _ in range(12)] == [False] * 11 + [True]
    buzz = _Path(sleep.Sleep(1e-3), lambda t: 1e-5 * np.sin(2.0 * np.pi * 70.0 * t))
    assert not any(buzz.frame(now) for _ in range(240))
