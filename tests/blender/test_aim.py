"""Hit the mark (addon/aim.py): a rigid body given a target and a frame is launched so its centre
is at the target then — within 1 mm, with and without damping — and a collision on the way is
reported."""
from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np
import pytest


def _scene(tmp_path: Path):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    scene.physanim.frame_start, scene.physanim.frame_end = 1, 60
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "aim.blend"))
    return scene


def _mark(location):
    mark = bpy.data.objects.new("Mark", None)
    bpy.context.scene.collection.objects.link(mark)
    mark.location = location
    return mark


@pytest.mark.parametrize("damping", [0.0, 0.8])
def test_a_ball_arrives_at_the_mark_at_the_frame(physanim_ext, tmp_path, damping):
    scene = _scene(tmp_path)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.3, location=(-4.0, 1.0, 1.0))
    ball = bpy.context.object
    p = ball.physanim.rigid_body
    p.enabled = True
    p.linear_damping = damping  # drag: "fraction of velocity lost per second"
    mark = _mark((3.0, -1.0, 2.5))
    p.target, p.target_frame = mark, 36
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    scene.frame_set(36)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    centre = np.array(ball.evaluated_get(depsgraph).matrix_world.translation)
    assert np.linalg.norm(centre - np.array(mark.location)) < 1e-3
    assert np.linalg.norm(p.initial_velocity) > 5.0  # it was thrown: the solve set it
    scene.frame_set(20)  # on its way, not there yet
    assert np.linalg.norm(np.array(ball.matrix_world.translation) - mark.location) > 1.0
    assert "hits something" not in scene.physanim.bake_info


def test_a_wall_in_the_way_is_reported(physanim_ext, tmp_path):
    scene = _scene(tmp_path)
    bpy.ops.mesh.primitive_cube_add(size=0.4, location=(-4.0, 0.0, 1.0))
    box = bpy.context.object
    box.physanim.rigid_body.enabled = True
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, 1.5))
    wall = bpy.context.object
    wall.scale = (0.1, 3.0, 3.0)
    wall.physanim.collider.enabled = True
    mark = _mark((4.0, 0.0, 1.0))
    box.physanim.rigid_body.target, box.physanim.rigid_body.target_frame = mark, 30
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert '"Cube" hits something on its way to "Mark" at frame' in scene.physanim.bake_info


def test_a_target_frame_outside_the_bake_is_refused(physanim_ext, tmp_path):
    _scene(tmp_path)
    bpy.ops.mesh.primitive_cube_add()
    box = bpy.context.object
    box.physanim.rigid_body.enabled = True
    box.physanim.rigid_body.target, box.physanim.rigid_body.target_frame = _mark((1, 1, 1)), 90
    with pytest.raises(RuntimeError, match=r"Target Frame 90 is not within the bake's frames "
                                           r"2-60"):
        bpy.ops.physanim.bake()
