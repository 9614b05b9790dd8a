"""The main job: build every sample scene, bake it headless, save it as a .blend and render the
frames that show each scene's point into an output folder.

    python tools/demo.py [--out OUT] [--scenes fountain,fireworks] [--frames 40,80] [--readme]

``--readme`` also writes each scene's README frame to docs/images/<scene>.png: the README's
pictures are exactly what this command renders.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import shutil
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tools import blender_env  # sets BLENDER_USER_RESOURCES before bpy is imported

import bpy

from sample_scenes import SCENES

ROOT = Path(__file__).resolve().parents[1]
README_IMAGES = ROOT / "docs" / "images"


@contextlib.contextmanager
def quiet_stdout():
    """Silence what Blender's C code prints to stdout (Cycles' per-sample progress lines), so
    the log has one line per step; Python prints go on as usual after it."""
    sys.stdout.flush()
    saved = os.dup(1)
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), 1)
    try:
        yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


@contextlib.contextmanager
def no_backups():
    """Saving keeps no .blend1 backup beside the file while this is active."""
    prefs = bpy.context.preferences.filepaths
    before = prefs.save_version
    prefs.save_version = 0
    try:
        yield
    finally:
        prefs.save_version = before


def render(scene, out: Path, name: str, frames: list[int]) -> list[Path]:
    images = []
    for frame in frames:
        scene.frame_set(frame)
        path = out / f"{name}_{frame:04d}.png"
        scene.render.filepath = str(path)
        start = time.perf_counter()
        with quiet_stdout():
            bpy.ops.render.render(write_still=True)
        print(f"[{name}] rendered frame {frame} in {time.perf_counter() - start:.1f} s: {path}",
              flush=True)
        images.append(path)
    return images


def run_scene(name: str, out: Path, frames: list[int] | None, readme: bool) -> list[str]:
    module = importlib.import_module(f"sample_scenes.{name}")
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    module.build(scene)
    blend = out / f"{name}.blend"
    with quiet_stdout():
        bpy.ops.wm.save_as_mainfile(filepath=str(blend))  # '//' cache paths need a saved file
    start = time.perf_counter()
    with quiet_stdout():  # Blender's own "Info:" lines; the bake's summary is printed below
        result = bpy.ops.physanim.bake()
    if 'FINISHED' not in result:
        return [f"{name}: bake did not finish: {scene.physanim.bake_info}"]
    print(f"[{name}] baked in {time.perf_counter() - start:.1f} s: {scene.physanim.bake_info}",
          flush=True)
    with quiet_stdout():
        bpy.ops.wm.save_mainfile()
    print(f"[{name}] saved {blend}", flush=True)
    problems = [f"{name}: {p}" for p in module.check(scene)]
    print(f"[{name}] self-check: {'; '.join(problems) if problems else 'passed'}", flush=True)
    wanted = frames or list(module.SHOWCASE)
    render(scene, out, name, wanted)
    if readme:
        if module.README_FRAME not in wanted:
            render(scene, out, name, [module.README_FRAME])
        picture = out / f"{name}_{module.README_FRAME:04d}.png"
        README_IMAGES.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(picture, README_IMAGES / f"{name}.png")
        print(f"[{name}] README picture: frame {module.README_FRAME} -> "
              f"{(README_IMAGES / f'{name}.png').relative_to(ROOT)}", flush=True)
    return problems


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out")
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--frames", default="",
                    help="frames to render (default: each scene's SHOWCASE frames)")
    ap.add_argument("--readme", action="store_true",
                    help="also write each scene's README frame to docs/images/<scene>.png")
    args = ap.parse_args(argv)
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    frames = [int(f) for f in args.frames.split(",") if f] or None
    blender_env.enable_extension()
    problems = []
    started = time.perf_counter()
    try:
        with no_backups():
            for name in args.scenes.split(","):
                problems += run_scene(name.strip(), out, frames, args.readme)
    finally:
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        blender_env.disable_extension()
    for p in problems:
        print("SELF-CHECK FAILED:", p)
    print(f"outputs in {out} ({time.perf_counter() - started:.0f} s)")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
