"""Hit the mark (addon/aim.py): a rigid body given a target and a frame is launched so its centre
is at the target then — within 1 mm, with and without damping — and a collision on the way is
reported."""
from __future__ import annotations

import sys
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


# -- particle bursts ------------------------------------------------------------------------------

def _emitter(location=(-4.0, 0.0, 1.0)):
    ob = bpy.data.objects.new("Spout", None)
    bpy.context.scene.collection.objects.link(ob)
    ob.location = location
    ob.physanim.emitter.enabled = True
    return ob


def _centre_of_first_births(ext, ob, frame: int) -> tuple[np.ndarray, int]:
    """The mean position at ``frame`` of the particles born in the emitter's first frame (the
    ids it shows at its Frame Start), read from the cache; and their count."""
    cache = sys.modules[f"{ext.__name__}.core.cache"]
    folder = bpy.path.abspath(ob.physanim.emitter.result.physanim.result.cache)
    first = cache.read_frame(folder, ob.physanim.emitter.frame_start)["id"]
    there = cache.read_frame(folder, frame)
    chosen = np.isin(there["id"], first)
    return there["position"][chosen].astype(float).mean(axis=0), int(chosen.sum())


def test_an_emitter_at_its_defaults_aims_its_stream_at_the_mark(physanim_ext, tmp_path):
    """An emitter at its defaults (a stream, 20 a frame, spread 15 degrees) given only a target
    and a frame: the centre of its first births is on the mark then, within 1 mm; the later
    births follow the same path (the emitter is still)."""
    _scene(tmp_path)
    spout = _emitter()
    mark = _mark((2.0, 1.0, 3.0))
    spout.physanim.emitter.target = mark
    spout.physanim.emitter.target_frame = 30
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    centre, count = _centre_of_first_births(physanim_ext, spout, 30)
    assert count >= 10
    assert np.linalg.norm(centre - np.array(mark.location)) < 1e-3
    assert np.linalg.norm(spout.physanim.emitter.launch_velocity) > 1.0  # the solve set it
    assert "hits something" not in bpy.context.scene.physanim.bake_info


def test_a_single_particle_burst_hits_the_mark_through_drag(physanim_ext, tmp_path):
    """One particle, no spread, a one-frame burst, with linear and quadratic drag: the
    particle itself is within 1 mm of the mark at the frame (drag bends the throw: the same
    launch without drag misses by more than half a metre)."""
    scene = _scene(tmp_path)
    spout = _emitter()
    p = spout.physanim.emitter
    p.rate, p.spread, p.frame_start, p.frame_end = 1.0, 0.0, 3, 3
    drag = bpy.data.objects.new("Drag", None)
    scene.collection.objects.link(drag)
    drag.physanim.force.enabled = True
    drag.physanim.force.type = 'DRAG'
    drag.physanim.force.linear, drag.physanim.force.quadratic = 0.05, 0.005
    mark = _mark((3.0, -2.0, 2.0))
    p.target, p.target_frame = mark, 40
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    centre, count = _centre_of_first_births(physanim_ext, spout, 40)
    assert count == 1
    assert np.linalg.norm(centre - np.array(mark.location)) < 1e-3
    # without drag the same launch overshoots: drag mattered
    drag.physanim.force.enabled = False
    p.target = None
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    free, _ = _centre_of_first_births(physanim_ext, spout, 40)
    assert np.linalg.norm(free - np.array(mark.location)) > 0.5


def test_a_wall_in_the_bursts_way_is_reported(physanim_ext, tmp_path):
    _scene(tmp_path)
    spout = _emitter((-4.0, 0.0, 1.0))
    p = spout.physanim.emitter
    p.frame_start = p.frame_end = 2
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, 1.5))
    wall = bpy.context.object
    wall.scale = (0.1, 3.0, 3.0)
    wall.physanim.collider.enabled = True
    p.target, p.target_frame = _mark((4.0, 0.0, 1.0)), 30
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert '"Spout" hits something on its way to "Mark" at frame' in \
        bpy.context.scene.physanim.bake_info
