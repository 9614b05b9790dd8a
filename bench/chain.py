"""Chain benchmark: a hinged chain draped over a box — physanim's constraints against Blender's
rigid body constraints (Bullet), same scene, same process. Prints a markdown table; nothing here
asserts a timing.

    tools/bench.sh chain [--links 100] [--frames 250]

``--links`` links of 10 cm, 2 cm thick, in a horizontal line 3 m up, each hinged to the next
about the horizontal axis across the chain, fall onto a 2 m box standing on the ground and drape
over it. Both simulators at their defaults (Blender: 10 substeps, 10 iterations; physanim: the
rigid-body defaults), the links rigid bodies of the default mass, the box a passive body /
Automatic collider, the chain's hinges made with each tool's own constraint. Beside the times:
the chain's stretch (the largest gap between neighbouring links' hinge points over the run, and
the total over the chain at its worst) — what a user sees of a chain that pulls apart.
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
LINK = 0.1  # [m]
THICK = 0.02  # [m]
HEIGHT = 3.0  # [m] of the chain at the start
BOX = 2.0  # [m]


def _mesh(name: str, size):
    import bmesh
    from mathutils import Matrix

    me = bpy.data.meshes.get(name)
    if me is None:
        me = bpy.data.meshes.new(name)
        bm = bmesh.new()
        bmesh.ops.create_cube(bm, size=1.0, matrix=Matrix.Diagonal((*size, 1.0)))
        bm.to_mesh(me)
        bm.free()
    return me


def scene_for(links: int, frames: int):
    """The chain (links along X, centred over the box), the box and one Empty per hinge at the
    shared end of two links (its Z along world Y)."""
    scene = blender_side.empty_scene(FPS, frames)
    me = _mesh("BenchLink", (LINK * 0.95, THICK, THICK))
    chain = []
    for i in range(links):
        ob = bpy.data.objects.new(f"Link{i:03d}", me)
        scene.collection.objects.link(ob)
        ob.location = ((i + 0.5 - links / 2) * LINK, 0.0, HEIGHT)
        chain.append(ob)
    box = bpy.data.objects.new("Box", _mesh("BenchBox", (BOX, BOX, BOX)))
    scene.collection.objects.link(box)
    box.location = (0.0, 0.0, BOX / 2)
    hinges = []
    for i in range(1, links):
        empty = bpy.data.objects.new(f"Hinge{i:03d}", None)
        scene.collection.objects.link(empty)
        empty.location = ((i - links / 2) * LINK, 0.0, HEIGHT)
        empty.rotation_euler = (-np.pi / 2, 0.0, 0.0)  # Z along +Y
        hinges.append(empty)
    return scene, chain, box, hinges


def _blender(scene, chain, box, hinges, frames):
    with bpy.context.temp_override(scene=scene):
        bpy.ops.rigidbody.world_add()
    world = scene.rigidbody_world
    world.point_cache.frame_start, world.point_cache.frame_end = 1, frames
    for ob in chain + [box]:
        with bpy.context.temp_override(object=ob, active_object=ob, selected_objects=[ob]):
            bpy.ops.rigidbody.object_add()
    box.rigid_body.type = 'PASSIVE'
    layer = bpy.context.view_layer
    for i, empty in enumerate(hinges):
        layer.objects.active = empty  # (the operator with a context override crashes 4.5)
        bpy.ops.rigidbody.constraint_add(type='HINGE')
        c = empty.rigid_body_constraint
        c.object1, c.object2 = chain[i], chain[i + 1]
    return world


def _physanim(scene, chain, box, hinges, frames):
    for ob in chain:
        ob.physanim.rigid_body.enabled = True
    box.physanim.collider.enabled = True
    for i, empty in enumerate(hinges):
        c = empty.physanim.constraint
        c.enabled, c.type, c.object1, c.object2 = True, 'HINGE', chain[i], chain[i + 1]
    scene.physanim.frame_start, scene.physanim.frame_end = 1, frames


def stretch(scene, chain, frames) -> tuple[float, float]:
    """(largest gap between neighbouring links' hinge points [m], the chain's total gap at its
    worst frame [m]) over the run."""
    worst, total = 0.0, 0.0
    for f in range(1, frames + 1):
        scene.frame_set(f)
        m = np.array([np.array(ob.matrix_world) for ob in chain])
        ends = m[:, :3, 3, None] + m[:, :3, 0, None] * np.array([-0.5, 0.5]) * LINK
        gaps = np.linalg.norm(ends[1:, :, 0] - ends[:-1, :, 1], axis=1)
        worst, total = max(worst, gaps.max()), max(total, gaps.sum())
    return worst, total


def run(kind: str, args, folder: str) -> dict:
    scene, chain, box, hinges = scene_for(args.links, args.frames)
    if kind == "blender":
        world = _blender(scene, chain, box, hinges, args.frames)
        start = time.perf_counter()
        for frame in range(1, args.frames + 1):
            scene.frame_set(frame)
        took = time.perf_counter() - start
        note = f"{world.substeps_per_frame} substeps, {world.solver_iterations} iterations"
    else:
        _physanim(scene, chain, box, hinges, args.frames)
        bpy.ops.wm.save_as_mainfile(filepath=str(Path(folder) / "chain.blend"))
        start = time.perf_counter()
        result = bpy.ops.physanim.bake()
        took = time.perf_counter() - start
        note = f"{scene.physanim.rigid_substeps} substeps" + ("" if result == {'FINISHED'}
                                                            else ", BAKE FAILED")
    worst, total = stretch(scene, chain, args.frames)
    low = min(ob.matrix_world.translation.z for ob in chain)
    return {"time": took, "note": note, "worst": worst, "total": total, "low": low}


def table(args, results: dict) -> str:
    rows = []
    base = results["blender"]["time"]
    for label, key in (("Blender rigid body constraints (Bullet, defaults)", "blender"),
                       ("physanim constraints (defaults, incl. keys)", "physanim")):
        r = results[key]
        rows.append((label, f"{r['time']:.2f}", f"{1000 * r['time'] / args.frames:.0f}",
                     f"{r['time'] / base:.2f}", f"{r['worst'] * 1000:.2f}",
                     f"{100 * r['total'] / (args.links * LINK):.2f}", r["note"]))
    ratio = results["physanim"]["time"] / base
    return "\n".join([
        "", f"### {args.links}-link hinged chain draped over a box, {args.frames} frames at {FPS} "
        f"fps, Blender {bpy.app.version_string}", "",
        *common.markdown_table(("simulator", "time (s)", "ms / frame", "ratio vs Blender",
                                "largest joint gap (mm)", "chain stretch (%)", "settings"),
                               "lrrrrrl", rows), "",
        f"- target: physanim <= 1.0 x Blender: {'met' if ratio <= 1.0 else 'NOT met'} "
        f"({ratio:.2f} x)"])


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--links", type=int, default=100)
    ap.add_argument("--frames", type=int, default=250)
    args = ap.parse_args(argv)
    results = {}
    with (tempfile.TemporaryDirectory(prefix="physanim_bench_") as folder,
          blender_side.extension_enabled()):
        for kind in ("blender", "physanim"):
            results[kind] = run(kind, args, folder)
    print(table(args, results))
    failed = "FAILED" in results["physanim"]["note"]
    return common.report(["physanim bake failed"] if failed else [])


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
