"""Follow-Through in Blender (addon/follow.py): a child trails its parent — keyframed or a rigid
body — through a damped spring, baked to Delta Location keys; checked against the damped
oscillator's closed form where the parent stops."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest


def _scene(tmp_path: Path, frame_end: int = 72):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = 24, 1.0
    scene.physanim.frame_start, scene.physanim.frame_end = 1, frame_end
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "follow.blend"))
    return scene


def _key_linear(ob, path: str, frames_values) -> None:
    for frame, value in frames_values:
        setattr(ob, path, value)
        ob.keyframe_insert(path, frame=frame)
    for fc in _curves(ob):
        for key in fc.keyframe_points:
            key.interpolation = 'LINEAR'


def _curves(ob):
    """The object's F-curves through its action (slotted or not): what Blender plays."""
    ad = ob.animation_data
    if ad is None or ad.action is None:
        return []
    if not hasattr(ad, "action_slot"):  # 4.2: legacy actions
        return list(ad.action.fcurves)
    return [fc for layer in ad.action.layers for strip in layer.strips
            for fc in strip.channelbag(ad.action_slot).fcurves]


def _child(parent, location=(0.0, 0.0, -1.0)):
    child = bpy.data.objects.new("Tail", None)
    bpy.context.scene.collection.objects.link(child)
    child.parent = parent
    child.location = location
    child.physanim.follow.enabled = True  # nothing else set: the defaults
    return child


def test_a_child_runs_on_where_its_parent_stops(physanim_ext, tmp_path):
    scene = _scene(tmp_path)
    parent = bpy.data.objects.new("Head", None)
    scene.collection.objects.link(parent)
    _key_linear(parent, "location", [(1, (0.0, 0.0, 2.0)), (25, (3.0, 0.0, 2.0))])
    child = _child(parent)
    child.rotation_euler = (0.0, 0.0, 0.5)
    child.keyframe_insert("rotation_euler", frame=1)  # its own animation stays
    assert bpy.ops.physanim.bake() == {'FINISHED'}

    p = child.physanim.follow
    w = 2.0 * math.pi * p.frequency
    wd = w * math.sqrt(1.0 - p.damping ** 2)
    u = 3.0 / (24 / 24.0)  # m/s: 3 m in 24 frames at 24 fps
    xs = []
    for frame in range(1, 73):
        scene.frame_set(frame)
        xs.append(child.matrix_world.translation.x)
    xs = np.array(xs)
    t = (np.arange(1, 73) - 25) / 24.0
    before, after = t < 0, t >= 0
    # it sets off with the parent, lagging as -(u / w_d) e^(-z w t) sin(w_d t) ...
    t0 = t[before] - t[0]
    np.testing.assert_allclose(xs[before] - u * t0,
                               -u / wd * np.exp(-p.damping * w * t0) * np.sin(wd * t0),
                               atol=1e-5)
    # ... and, where the parent stops, runs on past it and swings back
    lag = -u / wd * math.exp(-p.damping * w * 1.0) * math.sin(wd * 1.0)
    de = u / wd * (p.damping * w * math.sin(wd) - wd * math.cos(wd)) * math.exp(-p.damping * w)
    tau = t[after]
    overshoot = np.exp(-p.damping * w * tau) * (lag * np.cos(wd * tau) + (de + u + p.damping * w
                                                                         * lag) / wd
                                                * np.sin(wd * tau))
    np.testing.assert_allclose(xs[after] - 3.0, overshoot, atol=1e-5)
    assert xs.max() > 3.05  # it ran past where the parent stopped
    scene.frame_set(40)
    assert child.rotation_euler.z == pytest.approx(0.5)  # own animation untouched
    assert {fc.data_path for fc in _curves(child)} == {"rotation_euler", "delta_location"}
    panels = sys.modules[f"{physanim_ext.__name__}.addon.panels"]
    assert panels.bake_status(scene)[1] == 'CHECKMARK'
    p.damping = 0.5
    assert "outdated" in panels.bake_status(scene)[0] and "Tail" in panels.bake_status(scene)[0]

    assert bpy.ops.physanim.free_bake() == {'FINISHED'}
    assert {fc.data_path for fc in _curves(child)} == {"rotation_euler"}
    assert tuple(child.delta_location) == (0.0, 0.0, 0.0)


def test_a_rigid_body_parent_swings_its_child_on_impact(physanim_ext, tmp_path):
    scene = _scene(tmp_path, frame_end=48)
    bpy.ops.mesh.primitive_plane_add(size=10.0)
    bpy.context.object.physanim.collider.enabled = True
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, 3.0))
    cube = bpy.context.object
    cube.physanim.rigid_body.enabled = True
    child = _child(cube, location=(0.0, 0.0, 1.5))
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    offsets = []
    for frame in range(1, 49):
        scene.frame_set(frame)
        offsets.append(child.matrix_world.translation.z - cube.matrix_world.translation.z)
    offsets = np.array(offsets)
    assert offsets[0] == pytest.approx(1.5)
    assert offsets.min() < 1.5 - 0.02  # the cube lands and stops: the child runs on, down
    assert abs(offsets[-1] - 1.5) < abs(offsets.min() - 1.5)  # and swings back
    assert child.animation_data.action is not None and len(_curves(child)) == 3
    assert bpy.ops.physanim.free_bake() == {'FINISHED'}
    assert child.animation_data is None or child.animation_data.action is None


def test_a_follower_without_a_parent_is_refused(physanim_ext, tmp_path):
    _scene(tmp_path)
    loose = bpy.data.objects.new("Loose", None)
    bpy.context.scene.collection.objects.link(loose)
    loose.physanim.follow.enabled = True
    with pytest.raises(RuntimeError, match=r'follow-through "Loose" at frame 1: Follow-Through '
                                           r"trails the object's parent, and it has none"):
        bpy.ops.physanim.bake()
    assert loose.animation_data is None
