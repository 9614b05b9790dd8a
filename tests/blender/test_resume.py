"""Bakes that resume (addon/resume.py): a bake cut off — cancelled, or its process killed — goes
on from its last checkpoint, and a finished bake extends to a later frame end, both
bit-identical to a bake that ran through; a changed scene is refused, a fresh bake cleans up."""
from __future__ import annotations

import hashlib
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import bpy
import pytest

ROOT = Path(__file__).resolve().parents[2]


def _module(ext, name: str):
    return sys.modules[f"{ext.__name__}.addon.{name}"]


def _shot(folder: Path, frame_end: int = 24, cloth: int = 6) -> Path:
    """Every system: particles (USD points) on a ground collider, a spring mesh, three rigid
    boxes falling onto the ground."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "shot.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    scene = bpy.context.scene
    scene.physanim.frame_start, scene.physanim.frame_end = 1, frame_end
    bpy.ops.mesh.primitive_plane_add(size=10.0)
    bpy.context.object.physanim.collider.enabled = True
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(0.0, 0.0, 3.0))
    bpy.context.object.name = "Spray"
    bpy.context.object.physanim.emitter.enabled = True
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=cloth, y_subdivisions=cloth, size=1.0,
                                    location=(2.0, 0.0, 1.0))
    bpy.context.object.name = "Sheet"
    bpy.context.object.physanim.spring_mesh.enabled = True
    for i in range(3):
        bpy.ops.mesh.primitive_cube_add(size=0.5, location=(-2.0 + 0.1 * i, 0.0, 1.0 + 0.6 * i),
                                        rotation=(0.2 * i, 0.1, 0.0))
        bpy.context.object.physanim.rigid_body.enabled = True
    bpy.ops.wm.save_mainfile()
    return path


def _tree(folder: Path) -> dict[str, str]:
    """Every frame file of the finished bakes (not a meta.json, which records the time the bake
    took, nor partial folders or the checkpoint)."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != "meta.json"
            and not any(part == ".resume" or ".partial-" in part for part in p.parts)}


def _partials(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.rglob("*") if ".partial-" in p.name)


def _cut_off(bake, steps: int):
    """A bake stopped after ``steps`` frames, as Esc does (checkpoint every frame)."""
    job = bake.BakeJob(bpy.context, checkpoint_every=0)
    for _ in range(steps):
        job.step(bpy.context)
    job.suspend()
    return job


def _reference(bake, cache: Path) -> dict[str, str]:
    """An uninterrupted bake's files (the scene's first bake: later ones must equal it)."""
    assert bake.run(bpy.context)[1] is None
    return _tree(cache)


def test_a_cancelled_bake_resumes_bit_identical(physanim_ext, tmp_path):
    path = _shot(tmp_path / "shot")
    bake, resume = _module(physanim_ext, "bake"), _module(physanim_ext, "resume")
    cache = path.parent / "physanim_cache"
    reference = _reference(bake, cache)
    assert len(reference) > 70

    job = bake.BakeJob(bpy.context, checkpoint_every=0)
    while job.frame < 13:
        job.step(bpy.context)
    job.suspend()  # as Esc does
    assert _tree(cache) == reference  # the previous bake is untouched ...
    assert len(_partials(cache)) == 3  # ... and the frames so far are kept
    scene = bpy.context.scene
    text, can = resume.status(scene)
    assert can and text.startswith("Frames 1-13 of 1-24 cached (cut off)")

    info, failed = bake.run(bpy.context, resume=True)
    assert failed is None and "frames 1-24" in info
    assert _tree(cache) == reference
    assert _partials(cache) == []
    assert resume.status(scene) == ("Frames 1-24 cached", False)
    panels = _module(physanim_ext, "panels")
    assert panels.bake_status(scene)[1] == 'CHECKMARK'


def test_a_resumed_bake_leaves_a_killed_writers_temporary_files_behind(physanim_ext, tmp_path):
    """A process killed while USD saved a layer leaves its temporary file beside the frames
    (``points_000005.8ZnMNG``: the name's last number is not the frame's). The resumed bake
    takes the frames up to its checkpoint and nothing else: its files are an uninterrupted
    bake's, none of the temporary ones among them."""
    path = _shot(tmp_path / "shot")
    bake = _module(physanim_ext, "bake")
    cache = path.parent / "physanim_cache"
    reference = _reference(bake, cache)
    _cut_off(bake, 9)
    layers = [p.parent for p in cache.rglob("points_*") if ".partial-" in str(p)]
    assert layers
    for folder in set(layers):
        for stray in ("points_000005.8ZnMNG", "points_000005.AbCdEf", "frame_000004.npz.tmp"):
            (folder / stray).write_bytes(b"")
    info, failed = bake.run(bpy.context, resume=True)
    assert failed is None and "frames 1-24" in info
    assert _tree(cache) == reference


@pytest.mark.parametrize("scale", [0.4, 1.7])
def test_a_retimed_bake_resumes_bit_identical(physanim_ext, tmp_path, scale):
    """Under a Time Scale a step is a simulation frame showing several frames (or none): a bake
    cut off between them resumes where the simulation was, to the same files."""
    path = _shot(tmp_path / "shot")
    scene = bpy.context.scene
    scene.physanim.time_scale = scale
    bpy.ops.wm.save_mainfile()
    bake = _module(physanim_ext, "bake")
    cache = path.parent / "physanim_cache"
    reference = _reference(bake, cache)
    job = bake.BakeJob(bpy.context, checkpoint_every=0)
    while job.frame < 11:
        job.step(bpy.context)
    job.suspend()
    info, failed = bake.run(bpy.context, resume=True)
    assert failed is None and "frames 1-24" in info
    assert _tree(cache) == reference


def test_a_killed_bake_resumes_bit_identical(physanim_ext, tmp_path):
    """The process baking is killed outright (SIGKILL: no clean-up at all) mid-bake."""
    path = _shot(tmp_path / "shot", frame_end=60, cloth=24)
    bake, resume = _module(physanim_ext, "bake"), _module(physanim_ext, "resume")
    cache = path.parent / "physanim_cache"
    reference = _reference(bake, cache)
    bpy.ops.wm.save_mainfile()
    env = {k: v for k, v in os.environ.items() if k != "BLENDER_USER_RESOURCES"}
    env["PHYSANIM_CHECKPOINT_SECONDS"] = "0"
    process = subprocess.Popen([sys.executable, str(ROOT / "tools" / "physanim.py"), "bake",
                                str(path)], env=env, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    try:
        deadline = time.time() + 120
        checkpoint = resume.folder(bpy.context.scene) / resume.CHECKPOINT
        while time.time() < deadline:
            data = resume.load(bpy.context.scene)
            if data is not None and not data["finished"] and data["frame"] >= 20:
                break
            assert process.poll() is None, "the bake ended before it could be cut off"
            time.sleep(0.05)
        else:
            pytest.fail("no checkpoint at frame 20 within 2 minutes")
        process.send_signal(signal.SIGKILL)
        process.wait()
    finally:
        if process.poll() is None:
            process.kill()
    assert checkpoint.is_file() and _partials(cache)
    cut = resume.load(bpy.context.scene)["frame"]
    assert 20 <= cut < 60
    info, failed = bake.run(bpy.context, resume=True)
    assert failed is None
    assert _tree(cache) == reference
    assert _partials(cache) == []


def test_a_resumed_bake_names_the_frame_its_cloth_fell_asleep(physanim_ext, tmp_path):
    """A spring mesh asleep at the checkpoint (Sleep When Still) stays asleep from the frame it
    fell asleep at: the resumed bake's summary names that frame, not the first one it baked."""
    path = _shot(tmp_path / "shot", frame_end=48)
    for name in ("Spray", "Cube", "Cube.001", "Cube.002"):  # the sheet alone on the ground
        bpy.data.objects.remove(bpy.data.objects[name])
    bpy.ops.wm.save_mainfile()
    bake = _module(physanim_ext, "bake")
    cache = path.parent / "physanim_cache"
    reference = _reference(bake, cache)
    scene = bpy.context.scene
    summary = re.search(r'"Sheet" at rest \(asleep\) from frame (\d+)', scene.physanim.bake_info)
    assert summary is not None, scene.physanim.bake_info
    asleep = int(summary.group(1))
    assert asleep < 40
    job = bake.BakeJob(bpy.context, checkpoint_every=0)
    while job.frame < asleep + 4:
        job.step(bpy.context)
    job.suspend()
    info, failed = bake.run(bpy.context, resume=True)
    assert failed is None
    assert _tree(cache) == reference
    assert f'"Sheet" at rest (asleep) from frame {asleep}' in scene.physanim.bake_info


def test_a_checkpoint_names_only_frames_already_on_disk(physanim_ext, tmp_path, monkeypatch):
    """Frames go to disk on a writer thread: a checkpoint waits for them, so a process killed
    just after it leaves every frame it names whole (a resume keeps those files as they are)."""
    _shot(tmp_path / "shot")
    bake, resume = _module(physanim_ext, "bake"), _module(physanim_ext, "resume")
    cache_module = sys.modules[f"{physanim_ext.__name__}.core.cache"]
    save = cache_module._save

    def slow_save(path, arrays):  # a slow disk
        time.sleep(0.2)
        save(path, arrays)

    monkeypatch.setattr(cache_module, "_save", slow_save)
    job = bake.BakeJob(bpy.context, checkpoint_every=0)
    try:
        for _ in range(3):
            job.step(bpy.context)
            data = resume.load(bpy.context.scene)
            for key, folder in data["folders"].items():
                if key.startswith("emitter") or key == "rigid_bodies":
                    names = {p.name for p in Path(folder).rglob("frame_*.npz")}
                    assert f"frame_{data['frame']:06d}.npz" in names, (key, data["frame"])
    finally:
        job.abort()


def test_a_finished_bake_extends_to_a_later_frame_end(physanim_ext, tmp_path):
    path = _shot(tmp_path / "shot", frame_end=16)
    bake, resume = _module(physanim_ext, "bake"), _module(physanim_ext, "resume")
    cache = path.parent / "physanim_cache"
    assert bake.run(bpy.context)[1] is None
    scene = bpy.context.scene
    scene.physanim.frame_end = 26
    text, can = resume.status(scene)
    assert can and text == "Frames 1-16 cached: Resume extends the bake to 26"
    assert bake.run(bpy.context, resume=True)[1] is None
    extended = _tree(cache)
    shutil.rmtree(cache)
    assert bake.run(bpy.context)[1] is None  # one bake 1-26 from the start
    assert _tree(cache) == extended
    # nothing left to extend: Resume says so
    from physanim.core.errors import PhysanimError  # noqa: F401  (the source tree's name)
    with pytest.raises(Exception, match="nothing to resume: frames 1-26 are cached"):
        bake.run(bpy.context, resume=True)


def test_a_retimed_finished_bake_extends_to_the_same_files(physanim_ext, tmp_path):
    """At Time Scale 0.4 the last simulation frame of a 1-16 bake runs past frame 16: the
    extension to 26 starts from the state before it, and gives exactly the files of one bake
    1-26 (no frame missing or shifted)."""
    path = _shot(tmp_path / "shot", frame_end=16)
    scene = bpy.context.scene
    scene.physanim.time_scale = 0.4
    bpy.ops.wm.save_mainfile()
    bake = _module(physanim_ext, "bake")
    cache = path.parent / "physanim_cache"
    assert bake.run(bpy.context)[1] is None
    scene.physanim.frame_end = 26
    assert bake.run(bpy.context, resume=True)[1] is None
    extended = _tree(cache)
    shutil.rmtree(cache)
    assert bake.run(bpy.context)[1] is None
    assert _tree(cache) == extended
    assert sum(".npz" in name for name in extended) >= 26  # every frame of the emitter


def test_resuming_a_changed_scene_is_refused_and_a_fresh_bake_cleans_up(physanim_ext, tmp_path,
                                                                         capsys):
    path = _shot(tmp_path / "shot")
    bake, resume = _module(physanim_ext, "bake"), _module(physanim_ext, "resume")
    cache = path.parent / "physanim_cache"
    _cut_off(bake, 5)
    kept = _partials(cache)
    assert len(kept) == 3
    bpy.data.objects["Sheet"].physanim.spring_mesh.stiffness *= 2.0
    with pytest.raises(Exception, match=r"the scene changed since frames 1-6 were baked "
                                        r"\(spring_mesh Sheet\) — bake from the start"):
        bake.run(bpy.context, resume=True)
    assert _partials(cache) == kept  # refusing changes nothing
    cli = _module(physanim_ext, "cli")
    assert cli.main(["bake", "--resume"]) == 1
    assert "the scene changed since" in capsys.readouterr().out
    assert bake.run(bpy.context)[1] is None  # a fresh bake: the cut-off frames go
    assert _partials(cache) == []
    assert resume.status(bpy.context.scene) == ("Frames 1-24 cached", False)


def test_a_failed_bake_leaves_no_checkpoint_behind(physanim_ext, tmp_path):
    _shot(tmp_path / "shot")
    bake, resume = _module(physanim_ext, "bake"), _module(physanim_ext, "resume")
    job = bake.BakeJob(bpy.context, checkpoint_every=0)
    for _ in range(4):
        job.step(bpy.context)
    assert resume.load(bpy.context.scene)["frame"] == 5
    job.abort()  # what an error does
    assert resume.load(bpy.context.scene) is None
    assert _partials(tmp_path / "shot" / "physanim_cache") == []
    with pytest.raises(Exception, match="nothing to resume"):
        bake.run(bpy.context, resume=True)


def _checkpoint_bytes(cache: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in cache.rglob("*") if ".resume" in p.parts
            and p.is_file()}


def test_a_failed_bake_puts_back_the_checkpoint_of_the_bake_before(physanim_ext, tmp_path):
    """A bake that fails after it saved checkpoints leaves the scene's checkpoint as it was: a
    finished bake still extends, a cut-off one still resumes (its frames kept), a failed resume
    leaves the cut-off bake it went on from."""
    path = _shot(tmp_path / "shot", frame_end=12)
    bake, resume = _module(physanim_ext, "bake"), _module(physanim_ext, "resume")
    cache = path.parent / "physanim_cache"
    scene = bpy.context.scene
    assert bake.run(bpy.context)[1] is None
    finished = _checkpoint_bytes(cache)
    assert list(finished) == ["checkpoint.pkl"]

    def failed_after(steps: int, **kw) -> None:
        job = bake.BakeJob(bpy.context, checkpoint_every=0, **kw)
        for _ in range(steps):
            job.step(bpy.context)
        assert resume.load(scene)["frame"] > 1  # it replaced the checkpoint ...
        job.abort()  # ... and failed (what an error does)

    failed_after(3)
    assert _checkpoint_bytes(cache) == finished and _partials(cache) == []
    scene.physanim.frame_end = 16
    assert resume.status(scene) == ("Frames 1-12 cached: Resume extends the bake to 16", True)

    _cut_off(bake, 5)
    cut = _checkpoint_bytes(cache)
    kept = _partials(cache)
    assert len(kept) == 3
    failed_after(2)  # a fresh bake
    assert _checkpoint_bytes(cache) == cut and _partials(cache) == kept
    failed_after(2, resume=True)  # going on from the cut-off bake
    assert _checkpoint_bytes(cache) == cut and _partials(cache) == kept
    text, can = resume.status(scene)
    assert can and text.startswith("Frames 1-6 of 1-16 cached (cut off)")
    assert bake.run(bpy.context, resume=True)[1] is None
    assert _partials(cache) == []
    assert list(_checkpoint_bytes(cache)) == ["checkpoint.pkl"]
    assert resume.status(scene) == ("Frames 1-16 cached", False)


def test_the_panel_offers_resume_and_says_which_frames_are_cached(physanim_ext, tmp_path):
    _shot(tmp_path / "shot")
    bake, panels = _module(physanim_ext, "bake"), _module(physanim_ext, "panels")
    from physanim.tests.blender.probes import LabelRecorder

    _cut_off(bake, 7)
    labels: list[str] = []
    panels.draw_bake_buttons(LabelRecorder(labels), bpy.context.scene)
    assert any("Frames 1-8 of 1-24 cached (cut off): Resume continues from frame 8" in t
               for t in labels), labels
    assert bpy.ops.physanim.bake(resume=True) == {'FINISHED'}
    labels.clear()
    panels.draw_bake_buttons(LabelRecorder(labels), bpy.context.scene)
    assert "Frames 1-24 cached" in labels


def test_the_command_line_resumes(physanim_ext, tmp_path, capsys):
    path = _shot(tmp_path / "shot")
    bake, cli = _module(physanim_ext, "bake"), _module(physanim_ext, "cli")
    _cut_off(bake, 9)
    capsys.readouterr()
    assert cli.main(["bake", str(path), "--resume", "--save"]) == 0
    out = capsys.readouterr().out
    assert 'resuming frames 10-24 of scene "Scene" (frames 1-10 were baked)' in out
    assert "physanim: frame 9:" not in out and "physanim: frame 24:" in out
    assert _partials(tmp_path / "shot" / "physanim_cache") == []
