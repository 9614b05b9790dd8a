"""Memory reuse during a bake (``addon/allocator.py``): while a bake runs, freed state-sized
arrays are reused instead of being faulted in afresh; when it ends (finished or failed) glibc's
defaults are back. Counted in page faults (``ru_minflt``), not timed."""
from __future__ import annotations

import os
import platform
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest


def _glibc() -> bool:
    try:
        return platform.system() == "Linux" and os.confstr("CS_GNU_LIBC_VERSION").startswith(
            "glibc")
    except (ValueError, OSError):
        return False


pytestmark = pytest.mark.skipif(not _glibc(), reason="the allocator tuning is glibc's "
                                "(elsewhere it does nothing)")


def _allocator(ext):
    return sys.modules[f"{ext.__name__}.addon.allocator"]


def _spray(ext, folder: Path, frame_end: int):
    """A saved file with one emitter at its defaults baking frames 1..frame_end; returns the
    add-on's bake module."""
    scene = bpy.context.scene
    scene.physanim.frame_start, scene.physanim.frame_end = 1, frame_end
    ob = bpy.data.objects.new("Spray", None)
    scene.collection.objects.link(ob)
    ob.physanim.emitter.enabled = True  # the defaults
    bpy.ops.wm.save_as_mainfile(filepath=str(folder / "scene.blend"))
    return sys.modules[f"{ext.__name__}.addon.bake"]


def _faults_of_substeps(substeps: int = 10, arrays: int = 40) -> int:
    """Minor page faults of ``substeps`` rounds that each hold ``arrays`` fresh (100000, 3)
    float64 arrays at once (96 MB: a million-particle bake's passes hold more), then free
    them."""
    import resource  # Unix only (the module is skipped elsewhere)

    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(substeps):
        held = [np.ones((100_000, 3)) for _ in range(arrays)]
        del held
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before


def test_freed_arrays_are_reused_while_a_bake_holds_memory_and_returned_after(physanim_ext):
    allocator = _allocator(physanim_ext)
    pages = 10 * 40 * 100_000 * 3 * 8 // 4096  # every array faulted in afresh
    with allocator.reuse() as hold:
        assert hold.active
        _faults_of_substeps(2)  # the heap grows once ...
        reused = _faults_of_substeps()  # ... and is reused from then on
    after = _faults_of_substeps()
    assert reused < pages // 50, (reused, pages)
    # the bake's thresholds are gone: beyond glibc's settled trim threshold (64 MiB) the
    # memory goes back to the system again
    assert after > pages // 4, (after, pages)


def test_a_bake_holds_memory_reuse_until_it_ends_and_a_failed_one_lets_it_go(physanim_ext,
                                                                                tmp_path: Path):
    allocator = _allocator(physanim_ext)
    bake = _spray(physanim_ext, tmp_path, 6)
    users = []
    bake.run(bpy.context, on_frame=lambda job: users.append(allocator.GLIBC.users))
    assert users and all(u == 1 for u in users), users
    assert allocator.GLIBC.users == 0

    def fail(job):
        users.append(allocator.GLIBC.users)
        if job.frame >= 3:
            raise RuntimeError("stop here")

    users.clear()
    with pytest.raises(RuntimeError, match="stop here"):
        bake.run(bpy.context, on_frame=fail)
    assert users[-1] == 1 and allocator.GLIBC.users == 0


def test_a_cancelled_bake_whose_writer_failed_still_lets_memory_reuse_go(physanim_ext,
                                                                           tmp_path: Path):
    """Esc or Ctrl+C keeps the frames so far, but a writer that failed leaves nothing to keep:
    the job aborts (and lets go of the memory) whatever the writer raised."""
    allocator = _allocator(physanim_ext)
    bake = _spray(physanim_ext, tmp_path, 20)
    job = bake.BakeJob(bpy.context)
    for _ in range(3):
        job.step(bpy.context)
    assert allocator.GLIBC.users == 1

    def broken():
        raise ValueError("the writer thread failed")

    job.particles.flush = broken
    with pytest.raises(ValueError, match="writer thread failed"):
        job.suspend()
    assert allocator.GLIBC.users == 0
    assert not any(tmp_path.glob("physanim_cache/**/*.npz"))  # nothing kept
