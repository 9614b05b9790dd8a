"""Cloth benchmark: physanim's spring mesh (implicit) against Blender's cloth, same scene, same
process. Prints a markdown table; nothing here asserts a timing.

    tools/bench.sh cloth [--frames 250] [--grid 64]

The scene: a 2 x 2 m grid of 64 x 64 vertices at z = 2 m, pinned at the two corners of one
edge, falling under gravity for 250 frames at 24 fps.

* Blender: a Cloth modifier at default settings (quality 5 steps per frame) with the pin group,
  simulated by stepping ``scene.frame_set(1..F)`` from an empty point cache.
* physanim: the add-on path (spring mesh on the same object, IMPLICIT integrator, one step per
  frame, ``bpy.ops.physanim.bake()`` including writing the PC2 cache). Blender's cloth is not in
  SI units (its spring constant is tension / average spring length, its gravity is scaled), so
  the spring constants are matched by the outcome instead: stiff enough that the cloth hangs
  like Blender's (its lowest point within a few centimetres of Blender's at the last frame;
  the table shows both, and the run fails if they differ by more than 0.1 m).

Both runs are checked afterwards: every vertex finite, the pinned corners in place, the free
edge hanging below them.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from tools import blender_env  # noqa: E402  (sets BLENDER_USER_RESOURCES before bpy)

import bpy  # noqa: E402
import bmesh  # noqa: E402

FPS = 24
STIFFNESS = 6000.0  # N/m: the cloth then hangs as low as Blender's default cloth
SAME_HANG = 0.1  # m: largest allowed difference of the two cloths' lowest points


def build(grid: int, frames: int):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = FPS, 1.0
    scene.frame_start, scene.frame_end = 1, frames
    me = bpy.data.meshes.new("Cloth")
    bm = bmesh.new()
    bmesh.ops.create_grid(bm, x_segments=grid - 1, y_segments=grid - 1, size=1.0)
    bm.to_mesh(me)
    bm.free()
    ob = bpy.data.objects.new("Cloth", me)
    scene.collection.objects.link(ob)
    ob.location.z = 2.0
    co = np.array([v.co[:] for v in me.vertices])
    corners = [int(np.argmin(co[:, 0] - co[:, 1])), int(np.argmin(-co[:, 0] - co[:, 1]))]
    ob.vertex_groups.new(name="Pin").add(corners, 1.0, 'REPLACE')
    return scene, ob, corners


def world_vertices(ob) -> np.ndarray:
    me = ob.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    co = np.empty(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", co)
    m = np.array(ob.matrix_world)
    return co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]


def check(label: str, x: np.ndarray, rest: np.ndarray, corners: list[int]) -> list[str]:
    problems = []
    if not np.all(np.isfinite(x)):
        problems.append(f"{label}: non-finite vertices")
    if np.abs(x[corners] - rest[corners]).max() > 1e-3:
        problems.append(f"{label}: the pinned corners moved")
    if x[:, 2].min() > 1.0:
        problems.append(f"{label}: the cloth did not fall")
    return problems


def run_blender(grid: int, frames: int):
    scene, ob, corners = build(grid, frames)
    rest = world_vertices(ob)
    mod = ob.modifiers.new("Cloth", 'CLOTH')
    mod.settings.vertex_group_mass = "Pin"
    mod.point_cache.frame_start, mod.point_cache.frame_end = 1, frames
    start = time.perf_counter()
    for frame in range(1, frames + 1):
        scene.frame_set(frame)
    took = time.perf_counter() - start
    x = world_vertices(ob)
    return took, x, check("Blender cloth", x, rest, corners), mod.settings.quality


def run_physanim(grid: int, frames: int, folder: str):
    scene, ob, corners = build(grid, frames)
    rest = world_vertices(ob)
    p = ob.physanim.spring_mesh
    p.enabled = True
    p.mass = 0.3 * len(ob.data.vertices) / 100.0  # light cloth: 0.3 kg per 100 vertices
    p.stiffness, p.damping = STIFFNESS, 0.05
    p.shear_stiffness, p.shear_damping = STIFFNESS / 5.0, 0.01
    p.bend_mode, p.bend_stiffness, p.bend_damping = 'ANGULAR', 1e-3, 1e-5
    p.drag = 0.5
    p.pin_group = "Pin"
    scene.physanim.frame_start, scene.physanim.frame_end = 1, frames
    scene.physanim.integrator, scene.physanim.substeps = 'IMPLICIT', 1
    bpy.ops.wm.save_as_mainfile(filepath=str(Path(folder) / "cloth.blend"))
    start = time.perf_counter()
    result = bpy.ops.physanim.bake()
    took = time.perf_counter() - start
    scene.frame_set(frames)
    x = world_vertices(ob)
    problems = [] if result == {'FINISHED'} else ["physanim: bake failed"]
    return took, x, problems + check("physanim", x, rest, corners)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=250)
    ap.add_argument("--grid", type=int, default=64)
    args = ap.parse_args(argv)
    blender_env.enable_extension()
    problems = []
    try:
        with tempfile.TemporaryDirectory(prefix="physanim_bench_") as folder:
            b_time, b_x, b_problems, quality = run_blender(args.grid, args.frames)
            p_time, p_x, p_problems = run_physanim(args.grid, args.frames, folder)
            problems = b_problems + p_problems
            gap = abs(b_x[:, 2].min() - p_x[:, 2].min())
            if gap > SAME_HANG:
                problems.append(f"the cloths hang differently: lowest points {gap:.2f} m apart")
            bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    finally:
        blender_env.disable_extension()
    n = args.grid * args.grid
    print(f"\n### {args.grid} x {args.grid} grid ({n:,} vertices) pinned at two corners, "
          f"{args.frames} frames at {FPS} fps, Blender {bpy.app.version_string}\n")
    print("| simulator | time (s) | ms / frame | lowest point (m) | ratio vs Blender |")
    print("|---|---:|---:|---:|---:|")
    print(f"| Blender cloth (default, quality {quality}) | {b_time:.2f} | "
          f"{1000 * b_time / args.frames:.1f} | {b_x[:, 2].min():.2f} | 1.00 |")
    print(f"| physanim spring mesh (IMPLICIT, 1 step/frame, incl. PC2) | {p_time:.2f} | "
          f"{1000 * p_time / args.frames:.1f} | {p_x[:, 2].min():.2f} | {p_time / b_time:.2f} |")
    print("\n- target: physanim no slower than Blender's cloth (ratio <= 1.0): "
          f"{'met' if p_time <= b_time else 'NOT met'} ({p_time / b_time:.2f} x)")
    for p in problems:
        print("SANITY CHECK FAILED:", p)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
