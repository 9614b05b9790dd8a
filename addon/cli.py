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
    b.add_argument("--resume", action="store_true", help="go on from the last checkpoint: a bake "
                   "cut off (Ctrl+C, a killed process) continues where it stopped, a finished "
                   "one extends to the frame end (--frames A-B sets a new end)")
    f = sub.add_parser("free", help="free every PhysAnim bake of the scene")
    f.add_argument("blend", nargs="?")
    f.add_argument("--scene")
    f.add_argument("--save", action="store_true")
    c = sub.add_parser("check", help="list what a render on another machine (a farm node) "
                       "would miss: bakes missing or outdated, caches not on disk, absolute "
                       "paths, outputs that need the extension; exit code 1 if anything")
    c.add_argument("blend", nargs="?")
    c.add_argument("--scene")
    c.add_argument("--extension-on-farm", action="store_true",
                   help="the farm has PhysAnim installed (Points (Extension) outputs are fine)")
    r = sub.add_parser("render", help="check, then render frames, a log line each")
    r.add_argument("blend", nargs="?")
    r.add_argument("--scene")
    r.add_argument("--frames", required=True, help='frames: "7", "1-250", "1-250:5", "1,4,9-12"')
    r.add_argument("--output", help="output path with '#' for the frame number (default: the "
                   "scene's output path)")
    r.add_argument("--extension-on-farm", action="store_true")
    w = sub.add_parser("wedge", help="bake one combination of a wedge into its own cache "
                       "folder (wedge_NNN) and save it as <file>_wedge_NNN.blend beside the file")
    w.add_argument("blend", nargs="?")
    w.add_argument("--scene")
    w.add_argument("--spec", required=True, help='e.g. "Fountain:physanim.emitter.seed=1,2,3;'
                   '@scene:physanim.substeps=2,4" (every combination; the last varies fastest)')
    w.add_argument("--index", type=int, required=True, help="which combination, from 1")
    w.add_argument("--frames", help="frame range A-B to bake (default: the scene's)")
    t = sub.add_parser("sheet", help="contact sheet: one frame of every wedge in one PNG (and a "
                       "JSON naming each tile)")
    t.add_argument("blend", nargs="?")
    t.add_argument("--scene")
    t.add_argument("--spec", required=True)
    t.add_argument("--frame", type=int, required=True)
    t.add_argument("--output", required=True, help="PNG path")
    t.add_argument("--scale", type=int, default=50, help="resolution percent of each tile")
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
    command = {"bake": _bake_command, "free": _free_command, "check": _check_command,
               "render": _render_command, "wedge": _wedge_command,
               "sheet": _sheet_command}[args.command]
    return command(bpy.context.scene, args)


def _frame_range(scene, text: str | None, save: bool) -> bool:
    """Apply --frames A-B as the scene's PhysAnim range; False (logged) when malformed."""
    if not text:
        return True
    m = re.fullmatch(r"\s*(-?\d+)\s*-\s*(-?\d+)\s*", text)
    if not m:
        _log(f'error: --frames must look like 1-250 (got "{text}")')
        return False
    settings = scene.physanim
    was = (settings.frame_start, settings.frame_end)
    settings.frame_start, settings.frame_end = int(m[1]), int(m[2])
    _log(f"frame range {m[1]}-{m[2]} (the scene's PhysAnim range was {was[0]}-{was[1]}"
         f"{'; --save stores the new one' if save else ''})")
    return True


def _bake_command(scene, args) -> int:
    if not _frame_range(scene, args.frames, args.save):
        return 2
    only = None
    if args.objects:
        only = {n.strip() for n in args.objects.split(",") if n.strip()}
    if 'FINISHED' not in _bake(scene, only, args.resume):
        return 1
    return _save(args.save)


def _free_command(scene, args) -> int:
    try:
        result = bpy.ops.physanim.free_bake()
    except RuntimeError as exc:
        _log(f"error: {exc}")
        return 1
    if 'FINISHED' not in result:
        return 1
    return _save(args.save)


def _save(save: bool) -> int:
    if save:
        if not bpy.data.filepath:
            _log("error: --save needs a .blend file (pass one to open)")
            return 2
        bpy.ops.wm.save_mainfile()
        _log(f"saved {bpy.data.filepath}")
    return 0


def _check_command(scene, args) -> int:
    from . import farm

    problems = farm.farm_problems(scene, args.extension_on_farm)
    for problem in problems:
        _log(f"missing: {problem}")
    if problems:
        _log(f"error: {len(problems)} thing(s) a render elsewhere would miss in scene "
             f'"{scene.name}"')
        return 1
    _log(f'check: scene "{scene.name}" has everything a render elsewhere needs')
    return 0


def _render_command(scene, args) -> int:
    from . import farm

    try:
        frames = farm.parse_frames(args.frames)
    except ValueError as exc:
        _log(f"error: --frames: {exc}")
        return 2
    if _check_command(scene, args):
        _log("error: not rendering: fix the above (or re-bake) first")
        return 1
    farm.render_frames(scene, frames, args.output or scene.render.filepath, _log)
    return 0


def _wedge_setup(args):
    """(file, combinations) of a wedge command; None (logged) when either is unusable."""
    from . import farm

    if not bpy.data.filepath:
        _log("error: a wedge needs a saved .blend file (pass one to open)")
        return None
    try:
        return bpy.data.filepath, farm.wedge_combinations(args.spec)
    except ValueError as exc:
        _log(f"error: --spec: {exc}")
        return None


def _wedge_command(scene, args) -> int:
    from . import farm

    setup = _wedge_setup(args)
    if setup is None:
        return 2
    blend, combos = setup
    if not 1 <= args.index <= len(combos):
        _log(f"error: --index {args.index} is not one of the {len(combos)} combinations "
             f"(1-{len(combos)})")
        return 2
    combo = combos[args.index - 1]
    try:
        farm.apply_wedge(scene, combo)
    except ValueError as exc:
        _log(f"error: {exc}")
        return 2
    if not _frame_range(scene, args.frames, True):
        return 2
    root = scene.physanim.cache_dir.rstrip("/\\") or "//physanim_cache"
    scene.physanim.cache_dir = f"{root}/wedge_{args.index:03d}"
    _log(f"wedge {args.index} of {len(combos)}: {farm.wedge_label(combo)}; cache "
         f"{scene.physanim.cache_dir}")
    if 'FINISHED' not in _bake(scene, None):
        return 1
    target = farm.wedge_file(blend, args.index)
    bpy.ops.wm.save_as_mainfile(filepath=target, copy=True)
    _log(f"saved {target}")
    return 0


def _sheet_command(scene, args) -> int:
    import os

    from . import farm

    setup = _wedge_setup(args)
    if setup is None:
        return 2
    blend, combos = setup
    files = [farm.wedge_file(blend, i) for i in range(1, len(combos) + 1)]
    absent = [f for f in files if not os.path.isfile(f)]
    if absent:
        _log(f"error: {len(absent)} wedge file(s) not baked yet, e.g. {absent[0]}")
        return 1
    output = bpy.path.abspath(args.output)
    farm.contact_sheet(files, args.frame, output, [farm.wedge_label(c) for c in combos], _log,
                       args.scale)
    _log(f"contact sheet {output}")
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


def _bake(scene, only, resume: bool = False) -> set:
    from . import bake
    from ..core.errors import PhysanimError

    first = []

    def log_frame(job):
        if not first:
            first.append(job.frame)
            if job.frame == job.frame_start:
                _log(f'baking frames {job.frame_start}-{job.frame_end} of scene "{scene.name}"')
            else:
                _log(f'resuming frames {job.frame}-{job.frame_end} of scene "{scene.name}" '
                     f"(frames {job.frame_start}-{job.frame} were baked)")
        _log(f"frame {job.frame}: {job.contents}")

    try:
        info, failed = bake.run(bpy.context, only, log_frame, resume)
    except (PhysanimError, OSError, ValueError) as exc:
        _log(f"error: {exc}")
        return {'CANCELLED'}
    except KeyboardInterrupt:
        _log("interrupted: the frames baked so far are kept; bake --resume goes on from them")
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
