"""numpy's BLAS on one thread while a bake runs (``addon/blas.py``): OpenBLAS's own threads
wait for a core whenever something else keeps one busy (measured in the module's docstring),
so a bake runs BLAS on its own thread and gives the library's count back when it ends —
finished, failed or cancelled."""
from __future__ import annotations

import sys
from pathlib import Path

import bpy
import pytest


def _blas(ext):
    return sys.modules[f"{ext.__name__}.addon.blas"]


def _bake_module(ext, folder: Path, frame_end: int):
    """A saved file with one spring mesh at its defaults (a grid over a ground collider,
    frames 1..frame_end); returns the add-on's bake module."""
    scene = bpy.context.scene
    scene.physanim.frame_start, scene.physanim.frame_end = 1, frame_end
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=12, y_subdivisions=12, size=1.0,
                                    location=(0.0, 0.0, 0.5))
    bpy.context.active_object.physanim.spring_mesh.enabled = True
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    bpy.context.active_object.physanim.collider.enabled = True
    bpy.ops.wm.save_as_mainfile(filepath=str(folder / "scene.blend"))
    return sys.modules[f"{ext.__name__}.addon.bake"]


@pytest.fixture
def two_threads(physanim_ext):
    """The numpy wheels' OpenBLAS (every Blender build the tests run on ships one), set to two
    threads for the test (the test runner starts its workers at one) and set back after."""
    blas = _blas(physanim_ext).OPENBLAS
    assert blas.available, "numpy's OpenBLAS was not found among the loaded libraries"
    before = blas.threads()
    for lib in blas.libraries:
        lib.set_threads(2)
    yield blas
    for lib, count in zip(blas.libraries, before):
        lib.set_threads(count)


def test_openblas_is_found_and_its_thread_count_read_and_set(physanim_ext, two_threads):
    assert set(two_threads.threads()) == {2}
    hold = _blas(physanim_ext).OneThread()
    assert hold.active and set(two_threads.threads()) == {1}
    hold.end()
    hold.end()  # idempotent
    assert set(two_threads.threads()) == {2}
    assert two_threads.users == 0


def test_a_bake_runs_blas_on_one_thread_and_gives_the_count_back(physanim_ext, two_threads,
                                                                  tmp_path: Path):
    bake = _bake_module(physanim_ext, tmp_path, 5)
    seen = []
    bake.run(bpy.context, on_frame=lambda job: seen.append(two_threads.threads()))
    assert seen and all(set(t) == {1} for t in seen), seen
    assert set(two_threads.threads()) == {2} and two_threads.users == 0

    def fail(job):
        seen.append(two_threads.threads())
        if job.frame >= 3:
            raise RuntimeError("stop here")

    seen.clear()
    with pytest.raises(RuntimeError, match="stop here"):
        bake.run(bpy.context, on_frame=fail)
    assert set(seen[-1]) == {1} and set(two_threads.threads()) == {2} and two_threads.users == 0


def test_a_cancelled_bake_gives_the_count_back(physanim_ext, two_threads, tmp_path: Path):
    bake = _bake_module(physanim_ext, tmp_path, 12)
    job = bake.BakeJob(bpy.context)
    for _ in range(3):
        job.step(bpy.context)
    assert set(two_threads.threads()) == {1}
    job.suspend()  # Esc: the frames so far kept for a resume
    assert set(two_threads.threads()) == {2} and two_threads.users == 0
