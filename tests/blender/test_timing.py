"""Timing: the scene's Time Scale (simulated time per frame) for slow motion and speed ramps.

The simulation keeps its steps, so paths in space are those of scale 1: a bouncing rigid body,
particles and a spring mesh baked at 0.25 and resampled every fourth frame equal the scale-1
bake to 1e-6 m. Frames between simulation frames show the state between sub-steps; a keyed
ramp follows the closed form of a throw at the simulated time each frame shows.
"""
from __future__ import annotations

import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

from sample_scenes._common import result_points

G = 9.81
FPS = 24.0


def _core(ext, name: str):
    return sys.modules[f"{ext.__name__}.core.{name}"]


def _scene(tmp_path: Path, end: int, scale: float = 1.0, name: str = "timing.blend"):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    scene.physanim.frame_start, scene.physanim.frame_end = 1, end
    scene.physanim.time_scale = scale
    scene.frame_start, scene.frame_end = 1, end
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / name))
    return scene


def _ground():
    bpy.ops.mesh.primitive_plane_add(size=20.0)
    bpy.context.object.physanim.collider.enabled = True


def _ball(location=(0.0, 0.0, 2.0), velocity=(2.0, 0.0, 3.0)):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.3, location=location)
    ball = bpy.context.object
    ball.physanim.rigid_body.enabled = True
    ball.physanim.rigid_body.initial_velocity = velocity
    return ball


def _track(ob, frames) -> np.ndarray:
    scene = bpy.context.scene
    out = []
    for f in frames:
        scene.frame_set(f)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        out.append(np.array(ob.evaluated_get(depsgraph).matrix_world.translation))
    return np.array(out)


def _vertices(ob, frames) -> list[np.ndarray]:
    scene = bpy.context.scene
    out = []
    for f in frames:
        scene.frame_set(f)
        me = ob.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
        co = np.empty(len(me.vertices) * 3)
        me.vertices.foreach_get("co", co)
        out.append(co.reshape(-1, 3))
    return out


def _points(emitter, frames) -> list[dict]:
    scene = bpy.context.scene
    res = emitter.physanim.emitter.result
    out = []
    for f in frames:
        scene.frame_set(f)
        points = result_points(res)
        order = np.argsort(points["physanim_id" if "physanim_id" in points else "id"])
        out.append({k: v[order] for k, v in points.items()})
    return out


def _bake_everything(tmp_path: Path, scale: float, end: int):
    """A ball bouncing on the ground, a burst of particles bouncing too and a spring mesh
    falling onto it: every system, each at its defaults but for what makes it move."""
    scene = _scene(tmp_path, end, scale, f"scale_{scale}.blend")
    _ground()
    ball = _ball()
    emitter = bpy.data.objects.new("Burst", None)
    scene.collection.objects.link(emitter)
    emitter.location = (0.0, 3.0, 1.0)
    emitter.physanim.emitter.enabled = True
    emitter.physanim.emitter.frame_start = emitter.physanim.emitter.frame_end = 1
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=6, y_subdivisions=6, size=1.0,
                                    location=(0.0, -3.0, 1.0))
    cloth = bpy.context.object
    cloth.physanim.spring_mesh.enabled = True
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    return scene, ball, emitter, cloth


def test_slow_motion_keeps_every_path_in_space(physanim_ext, tmp_path):
    """Scale 1 over frames 1-25 and scale 0.25 over 1-97 simulate the same second: resampled
    every fourth frame, the ball, the particles and the spring mesh are where they were."""
    frames = range(1, 26)
    _, ball, emitter, cloth = _bake_everything(tmp_path, 1.0, 25)
    full = (_track(ball, frames), _points(emitter, frames), _vertices(cloth, frames))
    _, ball, emitter, cloth = _bake_everything(tmp_path, 0.25, 97)
    slow_frames = [1 + 4 * (f - 1) for f in frames]
    slow = (_track(ball, slow_frames), _points(emitter, slow_frames), _vertices(cloth, slow_frames))
    assert full[0][:, 2].min() < 0.31 and full[0][-1, 0] > 0.5  # it flew and bounced
    assert np.abs(full[0] - slow[0]).max() < 1e-6
    for a, b in zip(full[1], slow[1]):
        assert len(a["position"]) == len(b["position"]) > 0
        assert np.abs(a["position"] - b["position"]).max() < 1e-6
        assert np.abs(a["velocity"] - b["velocity"]).max() < 1e-5
    for a, b in zip(full[2], slow[2]):
        assert np.abs(a - b).max() < 1e-6
    # the frames between move on: a slow-motion ball passes through every quarter step
    between = _track(ball, range(1, 98))
    steps = np.linalg.norm(np.diff(between, axis=0), axis=1)
    assert (steps > 0.0).all()
    assert steps.max() < 0.5 * np.linalg.norm(np.diff(full[0], axis=0), axis=1).max()


def test_interpolated_frames_lie_on_the_throw(physanim_ext, tmp_path):
    """At scale 0.3 most frames fall between sub-steps: a thrown ball there is within the
    integrator's error of the closed form at the simulated time the frame shows."""
    scene = _scene(tmp_path, 40, 0.3)
    scene.physanim.rigid_substeps = 2
    x0, v0 = np.array([0.0, 0.0, 5.0]), np.array([3.0, 1.0, 4.0])
    ball = _ball(tuple(x0), tuple(v0))
    ball.physanim.rigid_body.linear_damping = 0.0  # the closed form has no drag
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    frames = np.arange(1, 41)
    t = (frames - 1) * 0.3 / FPS
    exact = x0 + v0 * t[:, None] + 0.5 * np.array([0.0, 0.0, -G]) * t[:, None] ** 2
    # first order in the step h: the discrete path lies within g t h of the parabola,
    # and a straight line between two sub-steps within g h^2 / 8 of the path
    h = 1.0 / FPS / 2
    error = np.linalg.norm(_track(ball, frames) - exact, axis=1)
    assert (error <= G * t * h + G * h * h / 8 + 1e-9).all(), error.max()
    assert error[1:].max() > 1e-5  # the frames are not sub-step ends only


def test_keyed_speed_ramp_follows_the_simulated_time(physanim_ext, tmp_path):
    """A ramp keyed 1 -> 0.2 -> 1 (linear keys): each frame shows the simulated time of the
    trapezoid rule over the keys, and the thrown ball is on the closed form there."""
    scene = _scene(tmp_path, 60)
    ps = scene.physanim
    for frame, value in ((1, 1.0), (20, 0.2), (40, 0.2), (60, 1.0)):
        ps.time_scale = value
        ps.keyframe_insert("time_scale", frame=frame)
    compat = sys.modules[f"{physanim_ext.__name__}.addon.compat"]
    for fc in compat.action_fcurves(scene.animation_data):
        for key in fc.keyframe_points:
            key.interpolation = 'LINEAR'
    x0, v0 = np.array([0.0, 0.0, 30.0]), np.array([2.0, 0.0, 6.0])
    ball = _ball(tuple(x0), tuple(v0))
    ball.physanim.rigid_body.linear_damping = 0.0
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    frames = np.arange(1, 61)
    scale = np.interp(frames, [1, 20, 40, 60], [1.0, 0.2, 0.2, 1.0])
    tau = np.concatenate([[0.0], np.cumsum(0.5 * (scale[1:] + scale[:-1]))])
    t = tau / FPS
    exact = x0 + v0 * t[:, None] + 0.5 * np.array([0.0, 0.0, -G]) * t[:, None] ** 2
    h = 1.0 / FPS / ps.rigid_substeps
    error = np.linalg.norm(_track(ball, frames) - exact, axis=1)
    assert (error <= G * t * h + G * h * h / 8 + 1e-9).all(), error.max()
    assert t[-1] == pytest.approx((19 * 0.6 + 20 * 0.2 + 20 * 0.6) / FPS)


def test_double_speed_skips_simulation_frames(physanim_ext, tmp_path):
    """At scale 2 each frame shows every other simulation frame of scale 1."""
    _scene(tmp_path, 21, 1.0, "one.blend")
    _ground()
    ball = _ball()
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    full = _track(ball, range(1, 22))
    _scene(tmp_path, 11, 2.0, "two.blend")
    _ground()
    ball = _ball()
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    fast = _track(ball, range(1, 12))
    assert np.abs(full[::2] - fast).max() < 1e-6


def test_time_scale_alone_bakes_and_changing_it_outdates(physanim_ext, tmp_path):
    """Only Time Scale set (0.5) on default objects of each role: the bake runs, each
    system's result spans every frame, and a new scale marks the bake outdated."""
    scene = _scene(tmp_path, 30, 0.5)
    _ground()
    _ball()
    emitter = bpy.data.objects.new("Emitter", None)
    scene.collection.objects.link(emitter)
    emitter.physanim.emitter.enabled = True
    bpy.ops.mesh.primitive_grid_add(location=(0.0, 3.0, 1.0))
    bpy.context.object.physanim.spring_mesh.enabled = True
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    panels = sys.modules[f"{physanim_ext.__name__}.addon.panels"]
    assert panels.bake_status(scene)[1] == 'CHECKMARK'
    scene.physanim.time_scale = 0.6
    assert "outdated" in panels.bake_status(scene)[0]


@pytest.mark.parametrize("limit, end, shows", [(0.01, 101, 2), (100.0, 2, 101)])
def test_time_scale_at_the_sliders_ends_bakes(physanim_ext, tmp_path, limit, end, shows):
    """The Time Scale slider's own ends bake, set or keyed (Blender keeps the value in single
    precision: 0.01 reads back as 0.0099999998, which was refused as below 0.01), and the last
    frame shows the simulated frame ``shows``: where a bake at scale 1 has the ball then."""
    _scene(tmp_path, shows, 1.0, "one.blend")
    ball = _ball()
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    reference = _track(ball, [shows])
    scene = _scene(tmp_path, end, limit, "limit.blend")
    ball = _ball()
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    track = _track(ball, range(1, end + 1))
    assert np.abs(track[-1] - reference[0]).max() < 1e-6
    for frame in (1, end):  # the same scale, keyed: read at every frame
        scene.physanim.keyframe_insert("time_scale", frame=frame)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert np.abs(_track(ball, range(1, end + 1)) - track).max() < 1e-9


def _drop(tmp_path: Path, name: str, **props):
    _scene(tmp_path, 70, 1.0, name)
    _ground()
    ball = _ball((0.0, 0.0, 3.0), (1.0, 0.0, 0.0))
    ball.physanim.rigid_body.restitution = 0.8  # a rubber ball (the default does not bounce)
    for key, value in props.items():
        setattr(ball.physanim.rigid_body, key, value)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    return _track(ball, range(1, 71))


def test_hang_time_alone_lingers_at_the_apex_and_lands_on_the_simulated_frames(physanim_ext,
                                                                               tmp_path):
    """A bouncing ball (the rigid-body defaults but its restitution), Hang Time 0.6 and
    nothing else: its keys touch down on the frames the simulation did, in the same places; around
    each apex it moves at under half its simulated speed, on the simulated path."""
    plain = _drop(tmp_path, "plain.blend")
    hung = _drop(tmp_path, "hang.blend", hang_time=0.6)
    low = np.nonzero((plain[1:-1, 2] < plain[:-2, 2]) & (plain[1:-1, 2] <= plain[2:, 2]))[0] + 1
    assert len(low) >= 2  # it bounced at least twice
    assert np.abs(hung[low] - plain[low]).max() < 1e-4
    top = np.nonzero((plain[1:-1, 2] > plain[:-2, 2]) & (plain[1:-1, 2] >= plain[2:, 2]))[0] + 1
    top = top[plain[top, 2] > 0.3 + 0.2]  # the jumps (the last hops are a frame or two long)
    assert len(top) >= 1
    for k in top:
        assert np.linalg.norm(hung[k + 1] - hung[k - 1]) < 0.5 * np.linalg.norm(
            plain[k + 1] - plain[k - 1])
    # on the path: x runs at the simulated (damped, nearly constant) speed, so the height at
    # each shown x is the simulated height there
    for k in top:
        seg = slice(k - 4, k + 5)
        assert np.interp(hung[seg, 0], plain[:, 0], plain[:, 2]) == pytest.approx(
            hung[seg, 2], abs=2e-3)


def test_bounce_exaggeration_alone_raises_each_bounce(physanim_ext, tmp_path):
    """Bounce Exaggeration 2 and nothing else: each bounce's apex rises twice as far above the
    line between its contacts; the contacts keep their frames and places."""
    plain = _drop(tmp_path, "plain.blend")
    high = _drop(tmp_path, "high.blend", exaggeration=2.0)
    low = np.nonzero((plain[1:-1, 2] < plain[:-2, 2]) & (plain[1:-1, 2] <= plain[2:, 2]))[0] + 1
    assert np.abs(high[low] - plain[low]).max() < 1e-4
    jumps = 0
    for a, b in zip(low[:-1], low[1:]):
        k = a + int(np.argmax(plain[a:b + 1, 2]))
        if plain[k, 2] < 0.3 + 0.2:
            continue  # a hop of a frame or two: no flight to shape
        jumps += 1
        # the line from take-off to landing: a low frame is the first after a bounce (the
        # contact falls between frames), so the flight is frames a .. b - 1
        line = np.interp(k, [a, b - 1], plain[[a, b - 1], 2])
        assert high[k, 2] - line == pytest.approx(2.0 * (plain[k, 2] - line), rel=0.01)
    assert jumps >= 1
    assert np.abs(high[:, :2] - plain[:, :2]).max() < 1e-6
