"""The Blender-side set-up the benchmarks share: an empty scene, a flat grid object, PhysAnim
enabled as an extension for a block, Blender's C-level printing silenced.

Import this module before ``bpy``: it imports :mod:`tools.blender_env`, which points
``BLENDER_USER_RESOURCES`` at a temp folder first. ``bpy`` itself is imported only when a function
here runs, so a benchmark's ``--help`` does not load Blender.
"""
from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator

from tools import blender_env


def reset() -> None:
    """Load Blender's factory-startup empty file (frees every object and point cache)."""
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)


def empty_scene(fps: int, frames: int):
    """A fresh empty file; its scene runs frames 1..``frames`` at ``fps``."""
    import bpy

    reset()
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = fps, 1.0
    scene.frame_start, scene.frame_end = 1, frames
    return scene


def grid_object(scene, name: str, segments: int, half_size: float, z: float):
    """A flat square grid facing +Z (``segments`` x ``segments`` faces, ``half_size`` [m] from the
    centre to an edge) as object and mesh ``name`` at height ``z`` [m], linked to ``scene``."""
    import bmesh
    import bpy

    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bmesh.ops.create_grid(bm, x_segments=segments, y_segments=segments, size=half_size)
    bm.to_mesh(me)
    bm.free()
    ob = bpy.data.objects.new(name, me)
    scene.collection.objects.link(ob)
    ob.location = (0.0, 0.0, z)
    return ob


@contextlib.contextmanager
def extension_enabled() -> Iterator:
    """PhysAnim enabled as an extension for the block (yields its module); afterwards an empty
    file is loaded and the extension disabled again."""
    module = blender_env.enable_extension()
    try:
        yield module
    finally:
        reset()
        blender_env.disable_extension()


@contextlib.contextmanager
def quiet_c_stdout() -> Iterator[None]:
    """Silence C-level stdout (``ptcache.bake`` prints one line per frame from C)."""
    sys.stdout.flush()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)
