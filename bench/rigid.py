"""Rigid-body benchmark: physanim's rigid bodies against Blender's rigid body world (Bullet),
same scenes, same process. Prints a markdown table; nothing here asserts a timing.

    tools/bench.sh rigid [--cubes 1000] [--frames 250] [--stack 10]

Pile: ``--cubes`` cubes of 0.5 m in a loose lattice, slightly turned, dropped onto a ground box,
falling into a pile for ``--frames`` frames at 24 fps.

* Blender: its rigid body world at its defaults (10 substeps per frame, 10 solver iterations),
  simulated by stepping ``scene.frame_set(1..F)`` from an empty cache.
* physanim: the add-on at its defaults (every cube a rigid body with nothing else set, the ground
  an Automatic collider), ``bpy.ops.physanim.bake()`` including writing the keys.

What a user sees of quality is printed beside the times: bodies still moving at the end, the
largest overlap between a cube and the ground at the end, and whether a ``--stack``-box stack
stands (a separate small scene, top box drift over the last 9 s).
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

FPS = 24
SIZE = 0.5  # [m] cube edge


def _cube(scene, name, location, rotation):
    me = bpy.data.meshes.get("BenchCube")
    if me is None:
        import bmesh
        me = bpy.data.meshes.new("BenchCube")
        bm = bmesh.new()
        bmesh.ops.create_cube(bm, size=SIZE)
        bm.to_mesh(me)
        bm.free()
    ob = bpy.data.objects.new(name, me)
    scene.collection.objects.link(ob)
    ob.location, ob.rotation_euler = location, rotation
    return ob


def _ground(scene):
    import bmesh
    me = bpy.data.meshes.new("BenchGround")
    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=1.0)
    bm.to_mesh(me)
    bm.free()
    ob = bpy.data.objects.new("Ground", me)
    scene.collection.objects.link(ob)
    ob.scale, ob.location = (400.0, 400.0, 1.0), (0.0, 0.0, -0.5)  # nothing falls off
    return ob


def pile_scene(cubes: int, frames: int):
    scene = blender_side.empty_scene(FPS, frames)
    side = int(np.ceil(np.sqrt(cubes / 10)))
    rng = np.random.default_rng(7)
    objects = []
    for k in range(cubes):
        layer, cell = divmod(k, side * side)
        i, j = divmod(cell, side)
        where = ((i - side / 2) * 0.8, (j - side / 2) * 0.8, 1.0 + layer * 0.8)
        objects.append(_cube(scene, f"Cube{k:04d}", where, tuple(rng.uniform(-0.3, 0.3, 3))))
    return scene, objects, _ground(scene)


def stack_scene(count: int, frames: int):
    scene = blender_side.empty_scene(FPS, frames)
    objects = [_cube(scene, f"Stack{k:02d}", (0.0, 0.0, SIZE / 2 + k * SIZE), (0, 0, 0))
               for k in range(count)]
    return scene, objects, _ground(scene)


def _blender_world(scene, objects, ground, frames):
    """Blender's rigid body world at its defaults: the cubes active, the ground passive."""
    with bpy.context.temp_override(scene=scene):
        bpy.ops.rigidbody.world_add()
    world = scene.rigidbody_world
    world.point_cache.frame_start, world.point_cache.frame_end = 1, frames
    for ob in objects + [ground]:
        with bpy.context.temp_override(object=ob, active_object=ob, selected_objects=[ob]):
            bpy.ops.rigidbody.object_add()
    ground.rigid_body.type = 'PASSIVE'
    return world


def _physanim(objects, ground, scene, frames):
    for ob in objects:
        ob.physanim.rigid_body.enabled = True
    ground.physanim.collider.enabled = True
    scene.physanim.frame_start, scene.physanim.frame_end = 1, frames


def run(kind: str, make, args, folder: str) -> dict:
    """One simulator on one scene: time, and what the user sees at the end."""
    scene, objects, ground = make()
    frames = scene.frame_end
    if kind == "blender":
        world = _blender_world(scene, objects, ground, frames)
        start = time.perf_counter()
        for frame in range(1, frames + 1):
            scene.frame_set(frame)
        took = time.perf_counter() - start
        note = f"{world.substeps_per_frame} substeps, {world.solver_iterations} iterations"
    else:
        _physanim(objects, ground, scene, frames)
        bpy.ops.wm.save_as_mainfile(filepath=str(Path(folder) / f"{make.__name__}.blend"))
        start = time.perf_counter()
        result = bpy.ops.physanim.bake()
        took = time.perf_counter() - start
        note = f"{scene.physanim.rigid_substeps} substeps" + ("" if result == {'FINISHED'}
                                                            else ", BAKE FAILED")
    return {"time": took, "note": note, **_seen(scene, objects, frames)}


def _seen(scene, objects, frames) -> dict:
    def poses(frame):
        scene.frame_set(frame)
        return np.array([np.array(o.matrix_world) for o in objects])

    last, before = poses(frames), poses(frames - 1)
    speed = np.linalg.norm(last[:, :3, 3] - before[:, :3, 3], axis=1) * FPS
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * SIZE / 2
    low = np.einsum("nij,cj->nci", last[:, :3, :3], corners)[..., 2] + last[:, None, 2, 3]
    return {"moving": int((speed > 0.01).sum()), "overlap": float(max(0.0, -low.min()))}


def stack_drift(kind: str, count: int, folder: str) -> float:
    """Largest drift [m] of a stack's top box over its last 9 s (of 10 s)."""
    frames = 10 * FPS
    scene, objects, ground = stack_scene(count, frames)
    if kind == "blender":
        _blender_world(scene, objects, ground, frames)
    else:
        _physanim(objects, ground, scene, frames)
        bpy.ops.wm.save_as_mainfile(filepath=str(Path(folder) / "stack.blend"))
        bpy.ops.physanim.bake()
    track = []
    for frame in range(1, frames + 1):
        scene.frame_set(frame)
        if frame > FPS:
            track.append(np.array(objects[-1].matrix_world.translation))
    track = np.array(track)
    return float(np.linalg.norm(track - track[0], axis=1).max())


def table(args, blender: dict, physanim: dict) -> str:
    rows = []
    for label, r in (("Blender rigid body world (Bullet, defaults)", blender),
                     ("physanim rigid bodies (defaults, incl. keys)", physanim)):
        stands = "stands" if r["drift"] < 1e-3 else f"drifts {r['drift'] * 1000:.1f} mm" \
            if r["drift"] < 0.1 else "falls"
        rows.append((label, f"{r['time']:.2f}", f"{1000 * r['time'] / args.frames:.0f}",
                     f"{r['time'] / blender['time']:.2f}", str(r["moving"]),
                     f"{r['overlap'] * 1000:.1f}", stands, r["note"]))
    ratio = physanim["time"] / blender["time"]
    return "\n".join([
        "", f"### {args.cubes:,} cubes falling into a pile, {args.frames} frames at {FPS} fps, "
        f"Blender {bpy.app.version_string}", "",
        *common.markdown_table(("simulator", "time (s)", "ms / frame", "ratio vs Blender",
                                "moving at end", "ground overlap (mm)",
                                f"{args.stack}-box stack", "settings"), "lrrrrrll", rows), "",
        f"- target: physanim <= 0.7 x Blender: {'met' if ratio <= 0.7 else 'NOT met'} "
        f"({ratio:.2f} x)"])


def main(argv: list[str]) -> int:
    """Pile and stack with each simulator -> table -> report."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cubes", type=int, default=1000)
    ap.add_argument("--frames", type=int, default=250)
    ap.add_argument("--stack", type=int, default=10)
    args = ap.parse_args(argv)
    results = {}
    with (tempfile.TemporaryDirectory(prefix="physanim_bench_") as folder,
          blender_side.extension_enabled()):
        for kind in ("blender", "physanim"):
            results[kind] = run(kind, lambda: pile_scene(args.cubes, args.frames), args, folder)
            results[kind]["drift"] = stack_drift(kind, args.stack, folder)
    print(table(args, results["blender"], results["physanim"]))
    problems = [] if results["physanim"]["note"].find("FAILED") < 0 else ["physanim bake failed"]
    return common.report(problems)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
