"""The command line (`blender -b -c physanim ...`): its handler ``addon.cli.main(argv)`` is called
directly, as Blender's ``-c`` would, and returns the exit code."""
from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import bmesh
import bpy
import pytest

from sample_scenes._common import result_points


@pytest.fixture
def cli(physanim_ext):
    return sys.modules[f"{physanim_ext.__name__}.addon.cli"]


def _shot(tmp_path: Path, names=("Fountain",), frame_end: int = 20) -> Path:
    """A saved .blend with small emitters; the current file is then emptied."""
    scene = bpy.context.scene
    scene.physanim.frame_start, scene.physanim.frame_end = 1, frame_end
    for i, name in enumerate(names):
        ob = bpy.data.objects.new(name, None)
        scene.collection.objects.link(ob)
        ob.location.x = 2.0 * i
        p = ob.physanim.emitter
        p.enabled = True
        p.rate, p.lifetime, p.speed, p.seed = 4.0, 6.0, 2.0, i
    path = tmp_path / "shot.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    return path


def _open(path: Path):
    bpy.ops.wm.open_mainfile(filepath=str(path))
    return bpy.context.scene


def _emitter_folder(path: Path, name: str) -> Path:
    """The bake folder of emitter ``name``: '<readable name>-<hash of the exact name>'."""
    import hashlib

    def folder(n: str) -> str:
        return f"{n}-{hashlib.sha1(n.encode()).hexdigest()[:8]}"
    return path.parent / "physanim_cache" / folder("Scene") / folder(name)


def test_main_is_the_registered_command_handler(cli):
    assert callable(cli.main)
    assert len(cli._handles) == 1  # register() hooked it up as `-c physanim`
    code = cli.main(["--help"])
    assert isinstance(code, int) and code == 0


def test_bake_frames_and_save(cli, tmp_path, capsys):
    path = _shot(tmp_path)

    assert cli.main(["bake", str(path), "--frames", "1-10", "--save"]) == 0

    out = capsys.readouterr().out
    for frame in range(1, 11):  # a line per frame, saying what is simulated
        assert f"physanim: frame {frame}:" in out
    assert "physanim: frame 10: " in out and " particles\n" in out and "rigid" not in out
    assert "physanim: frame 11:" not in out
    assert f"saved {path}" in out
    scene = _open(path)
    ob = scene.objects["Fountain"]
    res = ob.physanim.emitter.result
    assert res is not None and res.physanim.result.cache.startswith("//")
    assert (scene.physanim.frame_start, scene.physanim.frame_end) == (1, 10)
    meta = json.loads((_emitter_folder(path, "Fountain") / "meta.json").read_text())
    assert (meta["frame_start"], meta["frame_end"]) == (1, 10)
    emitter = bpy.data.objects["Fountain"]
    assert meta["hash"] == emitter.physanim.emitter.result.physanim.result.hash
    scene.frame_set(6)
    shown = result_points(res)
    assert len(shown["position"]) > 0 and len(shown["id"]) == len(shown["position"])


@pytest.mark.parametrize("scale", [0.5, 1.0, 2.0, 3.0])
def test_each_frame_is_logged_once_at_any_time_scale(cli, tmp_path, capsys, scale):
    """At double speed a simulation frame can end between two scene frames; its step showed no
    new frame and the log repeated the last one."""
    path = _shot(tmp_path)
    scene = _open(path)
    scene.physanim.time_scale = scale
    bpy.ops.wm.save_mainfile()
    capsys.readouterr()
    assert cli.main(["bake", str(path), "--frames", "1-10"]) == 0
    logged = [int(n) for n in re.findall(r"^physanim: frame (-?[0-9]+):",
                                          capsys.readouterr().out, re.MULTILINE)]
    assert logged == sorted(set(logged)) and logged[0] == 1 and logged[-1] == 10, logged


def test_bake_without_save_leaves_the_file(cli, tmp_path):
    path = _shot(tmp_path)
    before = path.read_bytes()
    assert cli.main(["bake", str(path), "--frames", "1-4"]) == 0
    assert path.read_bytes() == before
    assert bpy.data.objects["Fountain"].physanim.emitter.result is not None  # in memory only


def test_bake_only_the_named_objects(cli, tmp_path):
    path = _shot(tmp_path, names=("Left", "Middle", "Right"))

    assert cli.main(["bake", str(path), "--frames", "1-6", "--objects", "Left, Right",
                     "--save"]) == 0

    scene = _open(path)
    assert scene.objects["Left"].physanim.emitter.result is not None
    assert scene.objects["Right"].physanim.emitter.result is not None
    assert scene.objects["Middle"].physanim.emitter.result is None
    assert _emitter_folder(path, "Left").is_dir() and _emitter_folder(path, "Right").is_dir()
    assert not _emitter_folder(path, "Middle").exists()


@pytest.mark.parametrize("frames", ["x", "1-", "5:10", "1-2-3"])
def test_bad_frames_is_a_usage_error(cli, tmp_path, capsys, frames):
    path = _shot(tmp_path)
    code = cli.main(["bake", str(path), "--frames", frames, "--save"])
    assert code != 0
    assert frames in capsys.readouterr().out
    assert not (tmp_path / "physanim_cache").exists()


def test_bad_arguments_are_usage_errors(cli, tmp_path):
    path = _shot(tmp_path)
    assert cli.main([]) != 0
    assert cli.main(["explode", str(path)]) != 0
    assert cli.main(["bake", str(path), "--scene", "NoSuchScene"]) != 0
    assert not (tmp_path / "physanim_cache").exists()


def test_failing_bake_returns_1_and_prints_the_error(cli, tmp_path, capsys):
    path = _shot(tmp_path)
    scene = _open(path)
    me = bpy.data.meshes.new("Wire")
    bm = bmesh.new()
    a, b = bm.verts.new((0.0, 0.0, 0.0)), bm.verts.new((1.0, 0.0, 0.0))
    bm.edges.new((a, b))
    bm.to_mesh(me)
    bm.free()
    wire = bpy.data.objects.new("Wire", me)
    scene.collection.objects.link(wire)
    wire.physanim.emitter.enabled = True
    wire.physanim.emitter.source = 'FACES'
    bpy.ops.wm.save_mainfile()
    before = path.read_bytes()
    capsys.readouterr()

    assert cli.main(["bake", str(path), "--frames", "1-5", "--save"]) == 1

    out = capsys.readouterr().out
    assert 'physanim: error: emitter "Wire" at frame 1' in out and "no faces" in out
    assert path.read_bytes() == before  # not saved after a failure
    assert not (tmp_path / "physanim_cache").exists() or not any(
        p.is_file() for p in (tmp_path / "physanim_cache").rglob("*"))


def test_unknown_object_is_a_failure(cli, tmp_path, capsys):
    path = _shot(tmp_path)
    assert cli.main(["bake", str(path), "--objects", "Nope"]) == 1
    out = capsys.readouterr().out
    assert "error" in out and "Nope" in out


def test_free_removes_the_bake(cli, tmp_path):
    path = _shot(tmp_path, names=("A", "B"))
    assert cli.main(["bake", str(path), "--frames", "1-5", "--save"]) == 0
    assert _emitter_folder(path, "A").is_dir()

    assert cli.main(["free", str(path), "--save"]) == 0

    scene = _open(path)
    for name in ("A", "B"):
        ob = scene.objects[name]
        assert ob.physanim.emitter.enabled and ob.physanim.emitter.result is None
        assert not _emitter_folder(path, name).exists()
    assert "A_particles" not in bpy.data.objects and "B_particles" not in bpy.data.objects
    assert scene.physanim.bake_hash == ""


def test_missing_or_unreadable_blend_is_an_error_line(cli, tmp_path, capsys):
    assert cli.main(["bake", str(tmp_path / "nope.blend")]) == 1
    out = capsys.readouterr().out
    assert f'physanim: error: no such .blend file: "{tmp_path / "nope.blend"}"' in out
    junk = tmp_path / "junk.blend"
    junk.write_text("not a blend file")
    assert cli.main(["bake", str(junk), "--save"]) == 1
    out = capsys.readouterr().out
    assert "physanim: error:" in out and str(junk) in out
    assert junk.read_text() == "not a blend file"


def test_frames_says_it_sets_the_scene_range(cli, tmp_path, capsys):
    path = _shot(tmp_path, frame_end=20)
    assert cli.main(["bake", str(path), "--frames", "3-8"]) == 0
    out = capsys.readouterr().out
    assert "physanim: frame range 3-8 (the scene's PhysAnim range was 1-20)" in out
    assert cli.main(["bake", str(path), "--frames", "1-4", "--save"]) == 0
    assert "--save stores the new one" in capsys.readouterr().out


def test_bake_rigid_bodies_from_the_command_line(cli, tmp_path, capsys):
    """`--objects` naming one rigid body bakes them all (they push each other) and --save keeps
    the keys in the file; the progress lines count bodies, not particles."""
    scene = bpy.context.scene
    scene.physanim.frame_start, scene.physanim.frame_end = 1, 24
    for i, name in enumerate(("CrateA", "CrateB")):
        bpy.ops.mesh.primitive_cube_add(size=0.5, location=(0.0, 0.0, 1.0 + i))
        ob = bpy.context.object
        ob.name = name
        ob.physanim.rigid_body.enabled = True
    bpy.ops.mesh.primitive_plane_add(size=10.0)
    bpy.context.object.physanim.collider.enabled = True
    path = tmp_path / "crates.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)

    capsys.readouterr()
    assert cli.main(["bake", str(path), "--objects", "CrateA", "--save"]) == 0
    out = capsys.readouterr().out
    assert "physanim: frame 24: 2 rigid bodies\n" in out and "particles" not in out
    scene = _open(path)
    for name in ("CrateA", "CrateB"):
        ob = bpy.data.objects[name]
        assert ob.physanim.rigid_body.baked_action is not None
        scene.frame_set(24)
        assert ob.matrix_world.translation.z < 1.0 + 1.0 * (name == "CrateB")  # they fell
