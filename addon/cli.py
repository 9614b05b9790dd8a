"""Command line: ``blender -b [file.blend] -c physanim bake [file.blend] [--frames A-B]
[--objects NAMES] [--save]``. Synchronous, one log line per frame, non-zero exit on failure;
every error is one ``physanim: error: ...`` line.

``main(argv)`` is a plain function (tests call it directly, and ``tools/physanim.sh`` runs it
with the ``bpy`` module where there is no ``blender`` binary); ``register`` hooks it up as
Blender's ``-c physanim`` command.
"""
from __future__ import annotations

import argparse
import re

import bpy

_handles: list = []


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="blender -c physanim", description="PhysAnim from the command line")
    sub = p.add_subparsers(dest="command", required=True)
    b = sub.add_parser("bake", help="bake every PhysAnim system of the scene")
    b.add_argument("blend", nargs="?", help=".blend file to open (default: the one loaded)")
    b.add_argument("--frames", help="frame range A-B (default: the scene's PhysAnim range); it "
                   "becomes the scene's PhysAnim range, which --save stores in the file")
    b.add_argument("--objects", help="comma-separated names of the emitters and spring meshes "
                   "to bake (default: all)")
    b.add_argument("--scene", help="scene name (default: the active scene)")
    b.add_argument("--save", action="store_true", help="save the .blend after baking")
    f = sub.add_parser("free", help="free every PhysAnim bake of the scene")
    f.add_argument("blend", nargs="?")
    f.add_argument("--scene")
    f.add_argument("--save", action="store_true")
    return p


def _log(msg: str) -> None:
    print(f"physanim: {msg}", flush=True)


def main(argv: list[str]) -> int:
    """Run a PhysAnim command; returns the process exit code (0 = success)."""
    try:
        args = _parser().parse_args(argv)
    except SystemExit as exc:  # argparse exits on --help and on bad arguments
        return int(exc.code or 0) if isinstance(exc.code, int) else 2
    if args.blend and not _open(args.blend):
        return 1
    if args.scene:
        scene = bpy.data.scenes.get(args.scene)
        if scene is None:
            _log(f'error: no scene named "{args.scene}"')
            return 2
        bpy.context.window.scene = scene
    scene = bpy.context.scene
    if args.command == "bake":
        if args.frames:
            m = re.fullmatch(r"\s*(-?\d+)\s*-\s*(-?\d+)\s*", args.frames)
            if not m:
                _log(f'error: --frames must look like 1-250 (got "{args.frames}")')
                return 2
            settings = scene.physanim
            was = (settings.frame_start, settings.frame_end)
            settings.frame_start, settings.frame_end = int(m[1]), int(m[2])
            _log(f"frame range {m[1]}-{m[2]} (the scene's PhysAnim range was {was[0]}-{was[1]}"
                 f"{'; --save stores the new one' if args.save else ''})")
        only = None
        if args.objects:
            only = {n.strip() for n in args.objects.split(",") if n.strip()}
        result = _bake(scene, only)
    else:
        try:
            result = bpy.ops.physanim.free_bake()
        except RuntimeError as exc:
            _log(f"error: {exc}")
            return 1
    if 'FINISHED' not in result:
        return 1
    if args.save:
        if not bpy.data.filepath:
            _log("error: --save needs a .blend file (pass one to open)")
            return 2
        bpy.ops.wm.save_mainfile()
        _log(f"saved {bpy.data.filepath}")
    return 0


def _open(path: str) -> bool:
    """Open a .blend; an unreadable one is an error line, not a traceback."""
    import os

    if not os.path.isfile(path):
        _log(f'error: no such .blend file: "{path}"')
        return False
    try:
        bpy.ops.wm.open_mainfile(filepath=path)
    except RuntimeError as exc:  # Blender's message names the file and the reason
        _log(f"error: {str(exc).removeprefix('Error: ').strip()}")
        return False
    return True


def _bake(scene, only) -> set:
    from . import bake
    from ..core.errors import PhysanimError

    def log_frame(job):
        if job.frame == job.frame_start:
            _log(f'baking frames {job.frame_start}-{job.frame_end} of scene "{scene.name}"')
        _log(f"frame {job.frame}: {job.alive:,} particles")

    try:
        info, failed = bake.run(bpy.context, only, log_frame)
    except (PhysanimError, OSError, ValueError) as exc:
        _log(f"error: {exc}")
        return {'CANCELLED'}
    _log(info)
    if failed:  # the other systems baked; the exit code still says something failed
        _log(f"error: {failed}")
        return {'CANCELLED'}
    return {'FINISHED'}


def register() -> None:
    _handles.append(bpy.utils.register_cli_command("physanim", main))


def unregister() -> None:
    while _handles:
        bpy.utils.unregister_cli_command(_handles.pop())
