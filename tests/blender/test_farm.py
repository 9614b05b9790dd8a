"""Farm work: ``-c physanim check`` (what a render elsewhere would miss), ``render`` (frames after a
check), ``wedge`` and ``sheet``, and the Open Job Description templates in ``farm/openjd``,
validated with ``openjd check`` and run locally with ``openjd run`` on a small shot (the
``blender`` they call is ``tools/blender_shim.sh``: the bpy module with the same command line).
"""
from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

from sample_scenes._common import result_points

ROOT = Path(__file__).resolve().parents[2]
TEMPLATES = ROOT / "farm" / "openjd"


def _cli(ext):
    return sys.modules[f"{ext.__name__}.addon.cli"]


def _farm(ext):
    return sys.modules[f"{ext.__name__}.addon.farm"]


def _shot(folder: Path, frame_end: int = 6) -> Path:
    """An emitter and a spring mesh, a camera, Workbench at 64 x 48: saved, not baked."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    scene.physanim.frame_start, scene.physanim.frame_end = 1, frame_end
    bpy.ops.mesh.primitive_plane_add(size=1.0)
    emitter = bpy.context.object
    emitter.name = "Fountain"
    emitter.physanim.emitter.enabled = True
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=4, y_subdivisions=4, size=1.0,
                                    location=(2.0, 0.0, 1.0))
    sheet = bpy.context.object
    sheet.name = "Sheet"
    sheet.physanim.spring_mesh.enabled = True
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    camera.location = (1.0, -7.0, 1.0)
    camera.rotation_euler = (math.radians(88.0), 0.0, 0.0)
    scene.camera = camera
    scene.render.engine = 'BLENDER_WORKBENCH'
    scene.render.resolution_x, scene.render.resolution_y = 64, 48
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "shot.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def _check(ext, capsys, *args) -> tuple[int, str]:
    code = _cli(ext).main(["check", *args])
    return code, capsys.readouterr().out


def test_check_lists_what_a_farm_render_would_miss(physanim_ext, tmp_path, capsys):
    _shot(tmp_path / "shot")
    code, out = _check(physanim_ext, capsys)
    assert code == 1
    assert '"Fountain" is not baked' in out and '"Sheet" is not baked' in out

    assert bpy.ops.physanim.bake() == {'FINISHED'}
    code, out = _check(physanim_ext, capsys)
    assert code == 0 and "has everything" in out, out

    # the scene changes after the bake: outdated
    bpy.data.objects["Fountain"].physanim.emitter.rate = 5.0
    code, out = _check(physanim_ext, capsys)
    assert code == 1 and '"Fountain": the bake is outdated' in out
    bpy.data.objects["Fountain"].physanim.emitter.rate = 20.0
    assert _check(physanim_ext, capsys)[0] == 0

    # a cache that is not on disk (copied without it, deleted, ...)
    res = bpy.data.objects["Fountain"].physanim.emitter.result
    usd = Path(bpy.path.abspath(res.modifiers["physanim_cache"].cache_file.filepath)).parent
    next(usd.iterdir()).unlink()
    code, out = _check(physanim_ext, capsys)
    assert code == 1 and "5 USD point files for 6 baked frames" in out
    mesh_cache = Path(bpy.path.abspath(bpy.data.objects["Sheet"].modifiers["physanim"].filepath))
    mesh_cache.unlink()
    code, out = _check(physanim_ext, capsys)
    assert '"Sheet": mesh cache' in out and "is not on disk" in out


def test_check_names_absolute_paths_and_outputs_that_need_the_extension(physanim_ext, tmp_path,
                                                                        capsys):
    _shot(tmp_path / "shot")
    bpy.context.scene.physanim.cache_dir = str(tmp_path / "absolute_cache")
    bpy.data.objects["Fountain"].physanim.emitter.output = 'POINTS'
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    # the caches held at absolute paths (as after a bake of an unsaved file, or on another drive)
    res = bpy.data.objects["Fountain"].physanim.emitter.result
    res.physanim.result.cache = bpy.path.abspath(res.physanim.result.cache)
    sheet_cache = bpy.data.objects["Sheet"].modifiers["physanim"]
    sheet_cache.filepath = bpy.path.abspath(sheet_cache.filepath)
    code, out = _check(physanim_ext, capsys)
    assert code == 1
    assert '"Fountain": particle cache' in out and "is an absolute path" in out
    assert '"Sheet": mesh cache' in out
    assert 'Output "Points (Extension)" renders only where PhysAnim is installed' in out
    code, out = _check(physanim_ext, capsys, "--extension-on-farm")
    assert code == 1 and "Points (Extension)" not in out and "is an absolute path" in out


def test_render_checks_then_renders_each_frame(physanim_ext, tmp_path, capsys):
    path = _shot(tmp_path / "shot")
    cli = _cli(physanim_ext)
    assert cli.main(["render", "--frames", "2-3", "--output", "//out/f_##"]) == 1
    assert "not rendering" in capsys.readouterr().out
    assert not (path.parent / "out").exists()
    assert cli.main(["bake", "--save"]) == 0
    assert cli.main(["render", "--frames", "2-3,5", "--output", "//out/f_##"]) == 0
    out = capsys.readouterr().out
    for frame in (2, 3, 5):
        assert f"rendered frame {frame}:" in out
        assert (path.parent / "out" / f"f_{frame:02d}.png").is_file()
    assert not (path.parent / "out" / "f_04.png").exists()
    assert cli.main(["render", "--frames", "3-1"]) == 2
    assert "empty range" in capsys.readouterr().out


@pytest.mark.parametrize("text, frames", [("7", [7]), ("1-4", [1, 2, 3, 4]), ("1-9:4", [1, 5, 9]),
                                          ("5,1-3,2", [5, 1, 2, 3]), ("-2--1", [-2, -1])])
def test_frame_lists(physanim_ext, text, frames):
    assert _farm(physanim_ext).parse_frames(text) == frames


def test_wedge_bakes_each_combination_into_its_own_cache_and_file(physanim_ext, tmp_path,
                                                                  capsys):
    path = _shot(tmp_path / "shot")
    cli, farm = _cli(physanim_ext), _farm(physanim_ext)
    spec = "Fountain:physanim.emitter.speed=1,4;@scene:physanim.seed=3,9"
    combos = farm.wedge_combinations(spec)
    assert [[v for _t, _p, v in c] for c in combos] == [[1, 3], [1, 9], [4, 3], [4, 9]]
    for index in (1, 4):
        bpy.ops.wm.open_mainfile(filepath=str(path))
        assert cli.main(["wedge", "--spec", spec, "--index", str(index)]) == 0
    assert bpy.data.filepath == str(path)  # the shot itself stays as it was ...
    for index, (speed, seed) in ((1, (1, 3)), (4, (4, 9))):  # ... each wedge has its own file
        bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "shot" / f"shot_wedge_{index:03d}.blend"))
        scene = bpy.context.scene
        assert scene.physanim.seed == seed and scene.physanim.cache_dir.endswith(
            f"wedge_{index:03d}")
        fountain = bpy.data.objects["Fountain"]
        assert fountain.physanim.emitter.speed == speed
        assert _check(physanim_ext, capsys)[0] == 0  # baked, current, on disk
        scene.frame_set(6)
        shown = result_points(fountain.physanim.emitter.result)
        newborn = shown["age"] <= 1.0  # gravity has had at most a frame (0.41 m/s) on them
        speeds = np.linalg.norm(shown["velocity"][newborn], axis=1)
        assert len(speeds) > 5 and np.abs(speeds - speed).max() < 0.45  # the wedge's speed
    bpy.ops.wm.open_mainfile(filepath=str(path))
    assert bpy.context.scene.physanim.cache_dir == "//physanim_cache"
    assert not (tmp_path / "shot" / "physanim_cache" / "wedge_002").exists()


@pytest.mark.parametrize("spec, index, words", [
    ("Fountain:physanim.emitter.speed", 1, "must look like"),
    ("Nobody:physanim.emitter.speed=1", 1, 'no object named "Nobody"'),
    ("Fountain:physanim.emitter.sped=1", 1, 'no property "physanim.emitter.sped"'),
    ("Fountain:physanim.emitter.speed=1,2", 3, "not one of the 2 combinations"),
    ("Fountain:physanim.emitter.speed=fast", 1, "speed = 'fast'"),
    ("Fountain:location=1", 1, "location = 1"),
])
def test_wedge_errors_name_the_item(physanim_ext, tmp_path, capsys, spec, index, words):
    _shot(tmp_path / "shot")
    assert _cli(physanim_ext).main(["wedge", "--spec", spec, "--index", str(index)]) == 2
    assert words in capsys.readouterr().out


def test_a_keyframed_property_cannot_be_wedged(physanim_ext, tmp_path, capsys):
    _shot(tmp_path / "shot")
    fountain = bpy.data.objects["Fountain"]
    fountain.physanim.emitter.keyframe_insert("rate", frame=1)
    assert _cli(physanim_ext).main(["wedge", "--spec", "Fountain:physanim.emitter.rate=5",
                                    "--index", "1"]) == 2
    assert "is keyframed" in capsys.readouterr().out


# --- Open Job Description ------------------------------------------------------------------------

def _openjd() -> str:
    venv = subprocess.run(["bash", str(ROOT / "tools" / "venv.sh"), "farm"], capture_output=True,
                          text=True, check=True).stdout.strip().splitlines()[-1]
    return str(Path(venv) / "bin" / "openjd")


def _run_openjd(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "BLENDER_USER_RESOURCES"}
    env["PHYSANIM_BLENDER"] = f"{bpy.app.version[0]}.{bpy.app.version[1]}"  # this build
    return subprocess.run([_openjd(), *args], capture_output=True, text=True, cwd=cwd, env=env,
                          timeout=600)


@pytest.mark.parametrize("template", ["physanim_shot.yaml", "physanim_wedge.yaml"])
def test_templates_are_valid_open_job_descriptions(template, tmp_path):
    done = _run_openjd("check", str(TEMPLATES / template), cwd=tmp_path)
    assert done.returncode == 0 and "passes validation" in done.stdout, done.stdout + done.stderr


def test_shot_template_bakes_once_then_renders_chunks_that_wait_for_it(physanim_ext, tmp_path):
    path = _shot(tmp_path / "shot", frame_end=5)
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    done = _run_openjd("run", str(TEMPLATES / "physanim_shot.yaml"), "--step", "Render",
                       "--run-dependencies", "-p", f"BlendFile={path}", "-p", "Frames=1-5",
                       "-p", "FramesPerTask=2", "-p",
                       f"Blender={ROOT / 'tools' / 'blender_shim.sh'}", cwd=tmp_path)
    log = done.stdout + done.stderr
    assert done.returncode == 0, log[-3000:]
    assert log.count("physanim: baking frames 1-5") == 1
    bake_at = log.index("physanim: saved")
    for frame in range(1, 6):
        at = log.index(f"physanim: rendered frame {frame}:")
        assert at > bake_at  # every render runs after the bake
        assert (path.parent / "render" / f"frame_{frame:04d}.png").is_file()
    assert log.count("has everything a render elsewhere needs") == 3  # chunks 1-2, 3-4, 5


def test_wedge_template_bakes_each_wedge_then_a_contact_sheet(physanim_ext, tmp_path):
    path = _shot(tmp_path / "shot", frame_end=4)
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    spec = "Fountain:physanim.emitter.speed=0,6;@scene:physanim.seed=1,2,3"
    done = _run_openjd("run", str(TEMPLATES / "physanim_wedge.yaml"), "--step", "ContactSheet",
                       "--run-dependencies", "-p", f"BlendFile={path}", "-p", f"Spec={spec}",
                       "-p", "WedgeCount=6", "-p", "SheetFrame=4", "-p",
                       f"Blender={ROOT / 'tools' / 'blender_shim.sh'}", cwd=tmp_path)
    log = done.stdout + done.stderr
    assert done.returncode == 0, log[-3000:]
    folder = path.parent
    for index in range(1, 7):
        assert (folder / f"shot_wedge_{index:03d}.blend").is_file()
        assert (folder / "physanim_cache" / f"wedge_{index:03d}").is_dir()
    legend = json.loads((folder / "wedge_sheet.json").read_text())
    assert (legend["columns"], legend["rows"], len(legend["tiles"])) == (3, 2, 6)
    assert legend["tiles"][5]["values"] == "Fountain:physanim.emitter.speed=6, @scene:physanim.seed=3"
    image = bpy.data.images.load(str(folder / "wedge_sheet.png"))
    assert tuple(image.size) == (3 * 32, 2 * 24)  # 64 x 48 at 50 %, 3 x 2 tiles
    bpy.data.images.remove(image)
    shutil.rmtree(folder)
