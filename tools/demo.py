"""The main job: build every sample scene, bake it headless, save it as a .blend and render
preview images into an output folder.

    python tools/demo.py [--out OUT] [--scenes fountain,fireworks] [--frames 40,80]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tools import blender_env  # sets BLENDER_USER_RESOURCES before bpy is imported

import bpy

from sample_scenes import SCENES


def render(scene, out: Path, name: str, frames: list[int]) -> list[Path]:
    images = []
    for frame in frames:
        scene.frame_set(frame)
        path = out / f"{name}_{frame:04d}.png"
        scene.render.filepath = str(path)
        bpy.ops.render.render(write_still=True)
        images.append(path)
    return images


def run_scene(name: str, out: Path, frames: list[int] | None) -> list[str]:
    import importlib

    module = importlib.import_module(f"sample_scenes.{name}")
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    module.build(scene)
    blend = out / f"{name}.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))  # '//' cache paths need a saved file
    start = time.perf_counter()
    result = bpy.ops.physanim.bake()
    if 'FINISHED' not in result:
        return [f"{name}: bake did not finish"]
    print(f"[{name}] baked in {time.perf_counter() - start:.1f} s: {scene.physanim.bake_info}")
    bpy.ops.wm.save_mainfile()
    problems = [f"{name}: {p}" for p in module.check(scene)]
    end = scene.physanim.frame_end
    for path in render(scene, out, name, frames or [end // 3, (2 * end) // 3, end]):
        print(f"[{name}] rendered {path}")
    return problems


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out")
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--frames", default="", help="frames to render (default: three per scene)")
    args = ap.parse_args(argv)
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    frames = [int(f) for f in args.frames.split(",") if f] or None
    blender_env.enable_extension()
    problems = []
    try:
        for name in args.scenes.split(","):
            problems += run_scene(name.strip(), out, frames)
    finally:
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        blender_env.disable_extension()
    for p in problems:
        print("SELF-CHECK FAILED:", p)
    print(f"outputs in {out}")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
