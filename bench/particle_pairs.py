"""Particle collisions benchmark: physanim's particles colliding as spheres (a Particle
Collisions force object) against Blender's SPH fluid particles — Blender's only particles that
interact with each other — on the same emitter, same process. Prints a markdown table; nothing
here asserts a timing.

    tools/bench.sh sph [--count 100000] [--frames 50] [--emit 25]

The scene: a 2 x 2 m plane 1 m above a ground plane emits ``count`` particles (radius 1 cm, at
rest) over the first ``emit`` frames; they fall and pile up on the ground and on each other.

* Blender: a particle system at its defaults with Physics = Fluid (SPH, its default fluid
  settings) and particle size 0.01 m, the ground a Collision modifier, simulated by stepping
  ``scene.frame_set(1..F)`` from an empty point cache.
* physanim (headline row): the emitter at its defaults (speed 0, size 0.01 m) with a Particle
  Collisions force object and a ground collider, both at their defaults, the scene's default
  sub-steps, through ``bpy.ops.physanim.bake()`` including writing the point cache.

Afterwards, for both: particles alive, the lowest one, and how far neighbours sit inside each
other (the 1st percentile and the least of the nearest-neighbour distance over two radii).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench import blender_side, common  # blender_side first: it sets up Blender before bpy
import bpy

FPS = 25  # Blender's particle timestep defaults to 0.04 s/frame: 25 fps makes both agree
HEIGHT = 1.0  # [m] of the emitting plane
SIZE = 0.01  # [m] particle radius: 100,000 grains make a layer some 15 cm deep on the plane


def build(frames: int):
    scene = blender_side.empty_scene(FPS, frames)
    emitter = blender_side.grid_object(scene, "Emitter", 1, 1.0, HEIGHT)
    ground = blender_side.grid_object(scene, "Ground", 1, 10.0, 0.0)
    return scene, emitter, ground


def spacing(x: np.ndarray) -> tuple[float, float]:
    """(1st percentile, least) of each particle's nearest-neighbour distance over 2 radii."""
    neighbours = common.core_module("collision.neighbours")
    i, j = neighbours.neighbour_pairs(x, 2.0 * SIZE)
    nearest = np.full(len(x), 2.0 * SIZE)
    d = np.linalg.norm(x[i] - x[j], axis=1)
    np.minimum.at(nearest, i, d)
    np.minimum.at(nearest, j, d)
    ratio = nearest / (2.0 * SIZE)
    return float(np.percentile(ratio, 1)), float(ratio.min())


def run_blender(count: int, frames: int, emit: int):
    scene, emitter, ground = build(frames)
    emitter.modifiers.new("Particles", type='PARTICLE_SYSTEM')
    psys = emitter.particle_systems[0]
    s = psys.settings
    s.count = count
    s.frame_start, s.frame_end = 1, 1 + emit
    s.lifetime = frames + 50
    s.emit_from = 'FACE'
    s.normal_factor = 0.0
    s.particle_size = SIZE
    s.physics_type = 'FLUID'
    ground.modifiers.new("Collision", type='COLLISION')
    psys.point_cache.frame_start, psys.point_cache.frame_end = 1, frames
    note = f"SPH, {s.fluid.solver.lower()} solver, timestep {s.timestep:.3f} s"
    start = time.perf_counter()
    with blender_side.quiet_c_stdout():
        for frame in range(1, frames + 1):
            scene.frame_set(frame)
    took = time.perf_counter() - start
    depsgraph = bpy.context.evaluated_depsgraph_get()
    particles = emitter.evaluated_get(depsgraph).particle_systems[0].particles
    loc = np.empty(len(particles) * 3, np.float32)
    particles.foreach_get("location", loc)
    alive = np.empty(len(particles), np.int32)
    particles.foreach_get("alive_state", alive)
    x = loc.reshape(-1, 3)[alive == 3].astype(float)
    blender_side.reset()
    return took, x, note


def run_physanim(count: int, frames: int, emit: int, folder: str):
    scene, emitter, ground = build(frames)
    ground.physanim.collider.enabled = True
    p = emitter.physanim.emitter
    p.enabled = True
    p.source = 'FACES'
    p.rate = count / emit
    p.frame_start, p.frame_end = 2, 1 + emit
    p.lifetime = frames + 50
    p.speed = 0.0
    p.size = SIZE
    force = bpy.data.objects.new("Collisions", None)
    scene.collection.objects.link(force)
    force.physanim.force.enabled = True
    force.physanim.force.type = 'COLLISIONS'
    scene.physanim.frame_start, scene.physanim.frame_end = 1, frames
    bpy.ops.wm.save_as_mainfile(filepath=str(Path(folder) / "particle_pairs.blend"))
    start = time.perf_counter()
    result = bpy.ops.physanim.bake()
    took = time.perf_counter() - start
    problems = [] if result == {'FINISHED'} else ["physanim: bake failed"]
    scene.frame_set(frames)
    from sample_scenes._common import result_points

    x = result_points(p.result)["position"].astype(float)
    return took, x, problems, scene.physanim.substeps


def main(argv: list[str]) -> int:
    """Both runs with the extension enabled -> the table -> report."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=100_000)
    ap.add_argument("--frames", type=int, default=50)
    ap.add_argument("--emit", type=int, default=25)
    args = ap.parse_args(argv)
    with (tempfile.TemporaryDirectory(prefix="physanim_bench_") as folder,
          blender_side.extension_enabled()):
        b_time, b_x, b_note = run_blender(args.count, args.frames, args.emit)
        p_time, p_x, problems, substeps = run_physanim(args.count, args.frames, args.emit,
                                                      folder)
    rows = [(f"Blender particles, Physics Fluid ({b_note}; defaults)", b_time, b_x, 1.0),
            (f"physanim particles + Particle Collisions (defaults: {substeps} sub-steps; "
             "incl. cache)", p_time, p_x, p_time / b_time)]
    for label, x in (("Blender", b_x), ("physanim", p_x)):
        if abs(len(x) - args.count) > args.count // 100:
            problems.append(f"{label}: {len(x):,} particles at the end, not {args.count:,}")
    print("\n".join([
        "", f"### {args.count:,} particles from a 2 x 2 m plane 1 m up, piling on the ground, "
        f"{args.frames} frames at {FPS} fps, Blender {bpy.app.version_string}", "",
        *common.markdown_table(
            ("simulator", "time (s)", "ms / frame", "particles", "lowest (m)",
             "nearest neighbour / 2 r: 1st pct, least", "ratio vs Blender"), "lrrrrrr",
            [(label, f"{t:.2f}", f"{1000 * t / args.frames:,.0f}", f"{len(x):,}",
              f"{x[:, 2].min():.3f}" if len(x) else "-",
              "{:.2f}, {:.2f}".format(*spacing(x)) if len(x) > 1 else "-", f"{ratio:.2f}")
             for label, t, x, ratio in rows]), "",
        "- nearest neighbour / 2 r: 1 where spheres of the particles' radius touch, below 1 "
        "where they overlap (SPH particles are a fluid's samples, not solid grains)"]))
    common.print_final_load()
    return common.report(problems)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
