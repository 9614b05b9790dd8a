"""Separate processes: ``tools/physanim.sh``'s Python entry runs the ``-c physanim`` commands with
the bpy module, and two processes baking the same file write identical caches (the determinism
tests elsewhere compare two bakes within one process)."""
from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import bmesh
import bpy

ROOT = Path(__file__).resolve().parents[2]


def _shot(folder: Path) -> Path:
    """Every system at once: an emitter, a spring mesh (PC2) and an Automatic collider."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    scene.physanim.frame_start, scene.physanim.frame_end = 1, 12

    def mesh_object(name, build):
        me = bpy.data.meshes.new(name)
        bm = bmesh.new()
        build(bm)
        bm.to_mesh(me)
        bm.free()
        ob = bpy.data.objects.new(name, me)
        scene.collection.objects.link(ob)
        return ob

    ground = mesh_object("Ground", lambda bm: bmesh.ops.create_grid(
        bm, x_segments=1, y_segments=1, size=4.0))
    ground.physanim.collider.enabled = True
    emitter = mesh_object("Emitter", lambda bm: bmesh.ops.create_grid(
        bm, x_segments=1, y_segments=1, size=0.5))
    emitter.location.z = 1.0
    emitter.physanim.emitter.enabled = True
    sheet = mesh_object("Sheet", lambda bm: bmesh.ops.create_grid(
        bm, x_segments=6, y_segments=6, size=0.5))
    sheet.location = (2.0, 0.0, 0.6)
    sheet.physanim.spring_mesh.enabled = True
    folder.mkdir()
    path = folder / "shot.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    return path


def _run(*args: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "BLENDER_USER_RESOURCES"}
    return subprocess.run([sys.executable, str(ROOT / "tools" / "physanim.py"), *args],
                          capture_output=True, text=True, env=env, timeout=300)


def _hashes(folder: Path) -> dict[str, str]:
    """Every cache file (not the checkpoint: a pickle of the simulation state, whose bytes
    follow each process's string hashing)."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted((folder / "physanim_cache").rglob("*"))
            if p.is_file() and ".resume" not in p.parts}


def test_two_processes_bake_identical_caches(physanim_ext, tmp_path):
    first, second = _shot(tmp_path / "a"), tmp_path / "b"
    second.mkdir()
    (second / "shot.blend").write_bytes(first.read_bytes())

    runs = [_run("bake", str(folder / "shot.blend"), "--save") for folder in (first.parent, second)]

    for done in runs:
        assert done.returncode == 0, done.stdout + done.stderr
        assert "physanim: frame 12:" in done.stdout
    a, b = _hashes(first.parent), _hashes(second)
    assert any(name.endswith(".pc2") for name in a), a  # the spring mesh's cache is compared too
    assert len(a) >= 3 and a == b


def test_command_errors_are_one_line_and_exit_nonzero(tmp_path):
    done = _run("bake", str(tmp_path / "missing.blend"))
    assert done.returncode == 1
    assert f'physanim: error: no such .blend file: "{tmp_path / "missing.blend"}"' in done.stdout
    assert "Traceback" not in done.stdout + done.stderr
    usage = _run("bake", "--frames")
    assert usage.returncode == 2 and "usage:" in usage.stderr


_INSTALL_FROM_REPOSITORY = """
import sys, tempfile
sys.path.insert(0, sys.argv[1])
from tools import blender_env
import bpy
bpy.context.preferences.system.use_online_access = True
repos = bpy.context.preferences.extensions.repos
repo = repos.new(name="PhysAnim", module="physanim_remote", remote_url=sys.argv[2],
                 custom_directory=tempfile.mkdtemp(), source='USER')
index = list(repos).index(repo)
bpy.ops.extensions.repo_sync(repo_index=index)
bpy.ops.extensions.package_install(repo_index=index, pkg_id="physanim", enable_on_install=True)
module = "bl_ext.physanim_remote.physanim"
assert module in sys.modules, "not installed"
assert hasattr(bpy.ops.physanim, "bake")
blender_env.disable_extension(module)
print("installed", sys.modules[module].__file__)
"""


def test_build_makes_a_repository_blender_installs_from(tmp_path):
    """What the README's install section says: tools/build.sh's folder, added as a remote
    repository by its file:// URL, installs and enables the extension."""
    out = tmp_path / "dist"
    built = subprocess.run(["bash", str(ROOT / "tools" / "build.sh"), str(out)],
                           capture_output=True, text=True, timeout=300)
    assert built.returncode == 0, built.stdout + built.stderr
    assert built.stdout.strip().endswith(".zip") and (out / "index.json").is_file()
    env = {k: v for k, v in os.environ.items() if k != "BLENDER_USER_RESOURCES"}
    done = subprocess.run([sys.executable, "-c", _INSTALL_FROM_REPOSITORY, str(ROOT),
                           (out / "index.json").as_uri()],
                          capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "installed" in done.stdout and str(tmp_path) not in done.stdout.split("installed")[1]
