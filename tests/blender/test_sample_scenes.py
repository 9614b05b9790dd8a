"""Every sample scene builds into an empty file, bakes headless and passes its own self-check."""
from __future__ import annotations

import importlib
import sys
from pathlib import Path

import bpy
import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

SCENES = ("fountain", "fireworks", "robot_arm")


def test_every_sample_scene_is_tested():
    from sample_scenes import SCENES as listed

    assert set(listed) == set(SCENES)


@pytest.mark.parametrize("name", SCENES)
def test_sample_scene_bakes_and_passes_its_self_check(physanim_ext, tmp_path, name):
    module = importlib.import_module(f"sample_scenes.{name}")
    scene = bpy.context.scene
    module.build(scene)
    emitters = [o for o in scene.objects if o.physanim.emitter.enabled]
    assert emitters
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / f"{name}.blend"))

    assert bpy.ops.physanim.bake() == {'FINISHED'}

    assert all(o.physanim.emitter.result is not None for o in emitters)
    assert module.check(scene) == []
