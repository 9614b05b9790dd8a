"""Cloth benchmark: physanim's spring mesh (implicit) against Blender's cloth, same scene, same
process. Prints a markdown table; nothing here asserts a timing.

    tools/bench.sh cloth [--frames 250] [--grid 64] [--scenes dropped,suzanne,pinned]
                         [--repeat 1]

Three scenes, 250 frames at 24 fps each:

* **dropped** (the headline: the common case at both simulators' defaults): a 2 x 2 m grid of
  64 x 64 vertices 1 m above a 40 x 40 m ground plane falls onto it. Blender: a Cloth modifier
  and a Collision modifier on the ground, both at their defaults. physanim: the grid a spring
  mesh and the ground a collider, nothing else set. Checked: no vertex below the ground, the
  cloth lying on it at the end.
* **suzanne** (defaults too): the same grid from 2.5 m onto Suzanne (Blender's monkey, 2 m,
  face up, on the ground). Blender: Collision modifiers on Suzanne and the ground. physanim:
  both colliders, Suzanne's shape Mesh. Checked: no vertex below the ground, the cloth draped
  over her. Both dropped scenes also run physanim with Sleep When Still off and with the
  Implicit BDF2 integrator at one step per frame (labelled rows beside the defaults'
  headline), and say from which frame the defaults' cloth slept (its cache unchanged after)
  and how far from it the cloth with sleep off ends.
* **pinned**: the same grid at z = 2 m, pinned at the two corners of one edge, hanging under
  gravity (no collision): physanim at its defaults (the spring mesh's pin group named, nothing
  else set: the headline row), with the tuned settings below, and at the defaults with the
  Implicit BDF2 integrator at one step per frame (labelled). Beside the times: how far the
  vertices moved over the last frame, what is left of the swing (implicit Euler damps it).

* Blender: a Cloth modifier at default settings (quality 5 steps per frame) with the pin group,
  simulated by stepping ``scene.frame_set(1..F)`` from an empty point cache.
* physanim: the add-on path (spring mesh on the same object, ``bpy.ops.physanim.bake()``
  including writing the PC2 cache), at its defaults and tuned: IMPLICIT integrator, one step per
  frame, stiffer springs. Blender's cloth is not in SI units (its spring constant is tension / average spring length, its gravity is scaled), so
  the spring constants are matched by the outcome instead: stiff enough that the cloth hangs
  like Blender's (its lowest point within a few centimetres of Blender's at the last frame;
  the table shows both, and the run fails if they differ by more than 0.1 m). At the defaults
  the cloth is softer and hangs lower.

Both runs are checked afterwards: every vertex finite, the pinned corners in place, the free
edge hanging below them.

``--repeat N`` runs each scene's headline pair (Blender's cloth, then physanim at its defaults)
N times in turn, so that a machine whose speed drifts while it runs slows both sides of each
pair alike: the table shows the pair whose ratio is the median (the lower middle one for an
even N), a line under it every pair's ratio, and the target is judged on that pair (the
labelled rows run once).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from functools import partial
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench import blender_side, common  # blender_side first: it sets up Blender before bpy
import bpy

FPS = 24
STIFFNESS = 6000.0  # N/m: the cloth then hangs as low as Blender's default cloth
SAME_HANG = 0.1  # m: largest allowed difference of the two cloths' lowest points
DROP_HEIGHT = 1.0  # [m] the dropped cloth's start
GROUND_TOLERANCE = 1e-3  # [m] a vertex lower than this went through the ground
LYING = 0.1  # [m] at the end every vertex of the dropped cloth is this low or lower
DROPPED_TARGET = 0.8  # physanim / Blender time (issue 12)
SUZANNE_DROP = 2.5  # [m] the cloth's start over Suzanne
SUZANNE_TARGET = 1.0  # physanim / Blender time (issue 12)
PINNED_TARGET = 0.6  # physanim (defaults) / Blender time (issue 12)


def build(grid: int, frames: int):
    scene = blender_side.empty_scene(FPS, frames)
    ob = blender_side.grid_object(scene, "Cloth", grid - 1, 1.0, 2.0)
    co = np.array([v.co[:] for v in ob.data.vertices])
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


def build_dropped(grid: int, frames: int, suzanne: bool = False):
    """The cloth over a ground plane; with ``suzanne``, over Suzanne (Blender's monkey, 2 m,
    face up, resting on the ground) from higher up. Returns the scene, the cloth and the
    colliders."""
    scene = blender_side.empty_scene(FPS, frames)
    height = SUZANNE_DROP if suzanne else DROP_HEIGHT
    ob = blender_side.grid_object(scene, "Cloth", grid - 1, 1.0, height)
    colliders = [blender_side.grid_object(scene, "Ground", 1, 20.0, 0.0)]
    if suzanne:
        import bmesh
        me = bpy.data.meshes.new("Suzanne")
        bm = bmesh.new()
        bmesh.ops.create_monkey(bm)
        bm.to_mesh(me)
        bm.free()
        monkey = bpy.data.objects.new("Suzanne", me)
        scene.collection.objects.link(monkey)
        monkey.rotation_euler = (-1.5708, 0.0, 0.0)  # face up
        monkey.location = (0.0, 0.0, 0.85)
        colliders.append(monkey)
    return scene, ob, colliders


def check_dropped(label: str, x: np.ndarray, suzanne: bool = False) -> list[str]:
    """No vertex below the ground; on the ground alone, the cloth lying flat at the end; on
    Suzanne, draped over her (its highest vertex on her, its edges hanging half a metre and
    more below it)."""
    problems = []
    if not np.all(np.isfinite(x)):
        problems.append(f"{label}: non-finite vertices")
    elif x[:, 2].min() < -GROUND_TOLERANCE:
        problems.append(f"{label}: {int((x[:, 2] < -GROUND_TOLERANCE).sum())} vertices below "
                        f"the ground (lowest {x[:, 2].min():.3f} m)")
    elif suzanne:
        if not 1.0 < x[:, 2].max() < SUZANNE_DROP - 0.2 or np.ptp(x[:, 2]) < 0.5:
            problems.append(f"{label}: the cloth is not draped over Suzanne (z from "
                            f"{x[:, 2].min():.3f} to {x[:, 2].max():.3f} m)")
    elif x[:, 2].max() > LYING:
        problems.append(f"{label}: the cloth is not lying on the ground at the end (highest "
                        f"vertex {x[:, 2].max():.3f} m)")
    return problems


def run_blender_dropped(grid: int, frames: int, suzanne: bool = False):
    scene, ob, colliders = build_dropped(grid, frames, suzanne)
    mod = ob.modifiers.new("Cloth", 'CLOTH')
    mod.point_cache.frame_start, mod.point_cache.frame_end = 1, frames
    for collider in colliders:
        collider.modifiers.new("Collision", 'COLLISION')
    start = time.perf_counter()
    for frame in range(1, frames + 1):
        scene.frame_set(frame)
    took = time.perf_counter() - start
    x = world_vertices(ob)
    return took, x, check_dropped("Blender cloth", x, suzanne)


def run_physanim_dropped(grid: int, frames: int, folder: str, suzanne: bool = False,
                         bdf2: bool = False, sleep: bool = True):
    """The dropped cloth as a spring mesh at the defaults, or (``bdf2``) with the Implicit
    BDF2 integrator at one step per frame, or with Sleep When Still off (``sleep``)."""
    scene, ob, colliders = build_dropped(grid, frames, suzanne)
    ob.physanim.spring_mesh.enabled = True
    ob.physanim.spring_mesh.sleep = sleep
    if bdf2:
        ob.physanim.spring_mesh.integrator, ob.physanim.spring_mesh.substeps = 'BDF2', 1
    for collider in colliders:
        collider.physanim.collider.enabled = True
    if suzanne:
        colliders[1].physanim.collider.shape = 'MESH'  # (Automatic would choose it too)
    scene.physanim.frame_start, scene.physanim.frame_end = 1, frames
    bpy.ops.wm.save_as_mainfile(filepath=str(Path(folder) / "dropped.blend"))
    start = time.perf_counter()
    result = bpy.ops.physanim.bake()
    took = time.perf_counter() - start
    p = ob.physanim.spring_mesh
    integrator = scene.physanim.integrator if p.integrator == 'SCENE' else p.integrator
    settings = f"{integrator.lower()}, {p.substeps or scene.physanim.spring_substeps} substeps"
    scene.frame_set(frames)
    x = world_vertices(ob)
    problems = [] if result == {'FINISHED'} else ["physanim: bake failed"]
    return took, x, problems + check_dropped("physanim", x, suzanne), settings, slept(ob)


def slept(ob) -> int | None:
    """The first frame of the baked cache from which it never changes again (the mesh slept
    through the frames after it), or None."""
    path = bpy.path.abspath(ob.modifiers["physanim"].filepath)
    samples = common.core_module("pc2").read_pc2(path)[0]
    changed = [f for f in range(1, len(samples)) if not np.array_equal(samples[f],
                                                                        samples[f - 1])]
    last = changed[-1] + 1 if changed else 1
    return last if last < len(samples) - 1 else None


def dropped_table(grid: int, frames: int, blender: tuple, physanim: tuple,
                  suzanne: bool = False, bdf2: tuple | None = None,
                  awake: tuple | None = None) -> str:
    """The dropped scene's heading, table and target line; each run is ``(seconds, final
    world vertices (n, 3) [m])``, physanim's with its settings and the frame it slept from
    last (``bdf2``: the labelled row with Implicit BDF2 chosen, ``awake``: with Sleep When
    Still off). The target is judged on the defaults."""
    (b_time, b_x), (p_time, p_x, settings, asleep) = blender, physanim
    target, onto = ((SUZANNE_TARGET, f"Suzanne (a Mesh collider) on a ground plane from "
                     f"{SUZANNE_DROP} m") if suzanne else
                    (DROPPED_TARGET, f"a ground plane from {DROP_HEIGHT} m"))
    rows = [("Blender cloth + Collision (defaults)", f"{b_time:.2f}",
             f"{1000 * b_time / frames:.1f}", f"{b_x[:, 2].min():.3f}",
             f"{b_x[:, 2].max():.3f}", "1.00"),
            (f"physanim spring mesh + collider (defaults: {settings}, incl. PC2)",
             f"{p_time:.2f}", f"{1000 * p_time / frames:.1f}", f"{p_x[:, 2].min():.3f}",
             f"{p_x[:, 2].max():.3f}", f"{p_time / b_time:.2f}")]
    notes = []
    if awake is not None:
        t, x = awake
        rows.append(("physanim spring mesh + collider (defaults, Sleep When Still off, incl. "
                     "PC2)", f"{t:.2f}", f"{1000 * t / frames:.1f}", f"{x[:, 2].min():.3f}",
                     f"{x[:, 2].max():.3f}", f"{t / b_time:.2f}"))
        notes.append(f"- physanim at the defaults slept from frame "
                     f"{asleep if asleep is not None else '(never)'} on; with Sleep When Still "
                     f"off the cloth ends {1000 * np.abs(x - p_x).max():.3f} mm from it at most")
    if bdf2 is not None:
        t, x, label = bdf2
        rows.append((f"physanim spring mesh + collider (defaults, Implicit BDF2 chosen: "
                     f"{label}, incl. PC2)", f"{t:.2f}", f"{1000 * t / frames:.1f}",
                     f"{x[:, 2].min():.3f}", f"{x[:, 2].max():.3f}", f"{t / b_time:.2f}"))
    return "\n".join([
        "", f"### {grid} x {grid} grid ({grid * grid:,} vertices) dropped onto {onto}, "
        f"{frames} frames at {FPS} fps, Blender {bpy.app.version_string}",
        "", *common.markdown_table(("simulator", "time (s)", "ms / frame", "lowest z at end (m)",
                                    "highest z at end (m)", "ratio vs Blender"), "lrrrrr",
                                   rows), "",
        f"- target (issue 12): physanim <= {target} x Blender's cloth: "
        f"{'met' if p_time <= target * b_time else 'NOT met'} "
        f"({p_time / b_time:.2f} x)", *notes])


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
    return took, x, check("Blender cloth", x, rest, corners), mod.settings.quality, \
        motion(scene, ob, frames, x)


def motion(scene, ob, frames: int, x: np.ndarray) -> float:
    """Mean distance [mm] the vertices moved over the last frame (from the cache): how much
    of the swing is left."""
    scene.frame_set(frames - 1)
    before = world_vertices(ob)
    scene.frame_set(frames)
    return 1000.0 * float(np.linalg.norm(x - before, axis=1).mean())


def run_physanim(grid: int, frames: int, folder: str, mode: str):
    """The pinned cloth as a spring mesh: at the defaults (the pin group named, nothing else
    set), ``tuned`` (stiffer, hanging as Blender's does; one implicit step per frame) or
    ``bdf2`` (the defaults with the Implicit BDF2 integrator at one step per frame)."""
    tuned = mode == "tuned"
    scene, ob, corners = build(grid, frames)
    rest = world_vertices(ob)
    p = ob.physanim.spring_mesh
    p.enabled = True
    p.pin_group = "Pin"
    scene.physanim.frame_start, scene.physanim.frame_end = 1, frames
    if tuned:
        p.mass = 0.3 * len(ob.data.vertices) / 100.0  # light cloth: 0.3 kg per 100 vertices
        p.stiffness, p.damping = STIFFNESS, 0.05
        p.shear_stiffness, p.shear_damping = STIFFNESS / 5.0, 0.01
        p.bend_mode, p.bend_stiffness, p.bend_damping = 'ANGULAR', 1e-3, 1e-5
        p.drag = 0.5
        scene.physanim.integrator, scene.physanim.spring_substeps = 'IMPLICIT', 1
    if mode == "bdf2":
        p.integrator, p.substeps = 'BDF2', 1
    integrator = scene.physanim.integrator if p.integrator == 'SCENE' else p.integrator
    settings = f"{integrator.lower()}, {p.substeps or scene.physanim.spring_substeps} substeps"
    bpy.ops.wm.save_as_mainfile(filepath=str(Path(folder) / "cloth.blend"))
    start = time.perf_counter()
    result = bpy.ops.physanim.bake()
    took = time.perf_counter() - start
    scene.frame_set(frames)
    x = world_vertices(ob)
    problems = [] if result == {'FINISHED'} else ["physanim: bake failed"]
    return took, x, problems + check("physanim", x, rest, corners), settings, \
        motion(scene, ob, frames, x)


def cloth_table(grid: int, frames: int, quality: int, blender: tuple, runs: dict) -> str:
    """The heading, the table and the target line; ``quality`` is Blender's cloth quality, each
    run is ``(seconds, final world vertices (n, 3) [m], motion over the last frame [mm])``,
    physanim's (``runs``: by mode) with its settings last. The target is judged on the
    defaults' row."""
    b_time, b_x, b_motion = blender
    rows = [(f"Blender cloth (default, quality {quality})", f"{b_time:.2f}",
             f"{1000 * b_time / frames:.1f}", f"{b_x[:, 2].min():.2f}", f"{b_motion:.1f}",
             "1.00")]
    labels = {"defaults": "defaults", "tuned": "tuned",
              "bdf2": "defaults, Implicit BDF2 chosen"}
    for mode, (p_time, p_x, p_motion, settings) in runs.items():
        rows.append((f"physanim spring mesh ({labels[mode]}: {settings}, incl. PC2)",
                     f"{p_time:.2f}", f"{1000 * p_time / frames:.1f}", f"{p_x[:, 2].min():.2f}",
                     f"{p_motion:.1f}", f"{p_time / b_time:.2f}"))
    ratio = runs["defaults"][0] / b_time
    tuned = runs["tuned"]
    return "\n".join([
        "", f"### {grid} x {grid} grid ({grid * grid:,} vertices) pinned at two corners, "
        f"{frames} frames at {FPS} fps, Blender {bpy.app.version_string}", "",
        *common.markdown_table(("simulator", "time (s)", "ms / frame", "lowest point (m)",
                                "last frame's motion (mm)", "ratio vs Blender"), "lrrrrr",
                               rows), "",
        f"- target (issue 12): physanim at its defaults <= {PINNED_TARGET} x Blender's cloth: "
        f"{'met' if ratio <= PINNED_TARGET else 'NOT met'} ({ratio:.2f} x; tuned "
        f"{tuned[0] / b_time:.2f} x)"])


def paired(repeat: int, blender, physanim) -> tuple[list, list, list[float]]:
    """Run ``blender()`` then ``physanim()`` ``repeat`` times in turn (each returns its time
    first): (Blender's results, physanim's, the ratios), the pairs ordered by ratio."""
    pairs = []
    for _ in range(max(1, repeat)):
        b = blender()
        pairs.append((b, physanim()))
    pairs.sort(key=lambda pair: pair[1][0] / pair[0][0])
    return [b for b, _ in pairs], [p for _, p in pairs], [p[0] / b[0] for b, p in pairs]


def ratios_note(ratios: list[float]) -> list[str]:
    """The line under a table of paired runs (none for one run)."""
    if len(ratios) < 2:
        return []
    return [f"- {len(ratios)} pairs run in turn, ratios {', '.join(f'{r:.2f}' for r in ratios)}"
            f": the table shows the {'median' if len(ratios) % 2 else 'lower middle'} pair "
            f"({ratios[(len(ratios) - 1) // 2]:.2f} x)"]


def main(argv: list[str]) -> int:
    """Both runs with the extension enabled -> the same-hang check -> the table -> report."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=250)
    ap.add_argument("--grid", type=int, default=64)
    ap.add_argument("--scenes", default="dropped,suzanne,pinned",
                    help="comma list of: dropped, suzanne, pinned (defaults and tuned)")
    ap.add_argument("--repeat", type=int, default=1,
                    help="headline pairs (Blender, then physanim at its defaults) run in turn "
                         "per scene; the median pair is shown and judged")
    args = ap.parse_args(argv)
    scenes = {k.strip() for k in args.scenes.split(",") if k.strip()}
    known = {"dropped", "suzanne", "pinned"}
    if scenes - known:
        ap.error(f"unknown scenes {sorted(scenes - known)}")
    problems = []
    with (tempfile.TemporaryDirectory(prefix="physanim_bench_") as folder,
          blender_side.extension_enabled()):
        for suzanne in [s == "suzanne" for s in ("dropped", "suzanne") if s in scenes]:
            blenders, ours, ratios = paired(
                args.repeat, partial(run_blender_dropped, args.grid, args.frames, suzanne),
                partial(run_physanim_dropped, args.grid, args.frames, folder, suzanne))
            for run in blenders + ours:
                problems += run[2]
            middle = (len(ratios) - 1) // 2
            b_time, b_x, _ = blenders[middle]
            p_time, p_x, _, settings, asleep = ours[middle]
            a_time, a_x, a_problems, _, _ = run_physanim_dropped(
                args.grid, args.frames, folder, suzanne, sleep=False)
            d_time, d_x, d_problems, d_settings, _ = run_physanim_dropped(
                args.grid, args.frames, folder, suzanne, bdf2=True)
            problems += a_problems + d_problems
            print("\n".join([dropped_table(args.grid, args.frames, (b_time, b_x),
                                           (p_time, p_x, settings, asleep), suzanne,
                                           (d_time, d_x, d_settings), (a_time, a_x)),
                             *ratios_note(ratios)]), flush=True)
        if "pinned" in scenes:
            blenders, ours, ratios = paired(
                args.repeat, lambda: run_blender(args.grid, args.frames),
                lambda: run_physanim(args.grid, args.frames, folder, "defaults"))
            for run in blenders + ours:
                problems += run[2]
            middle = (len(ratios) - 1) // 2
            b_time, b_x, _, quality, b_motion = blenders[middle]
            p_time, p_x, _, settings, p_motion = ours[middle]
            runs = {"defaults": (p_time, p_x, p_motion, settings)}
            for mode in ("tuned", "bdf2"):
                p_time, p_x, p_problems, settings, p_motion = run_physanim(
                    args.grid, args.frames, folder, mode)
                problems += p_problems
                runs[mode] = (p_time, p_x, p_motion, settings)
            gap = abs(b_x[:, 2].min() - runs["tuned"][1][:, 2].min())
            if gap > SAME_HANG:
                problems.append(f"the tuned cloth hangs differently from Blender's: lowest "
                                f"points {gap:.2f} m apart")
            print("\n".join([cloth_table(args.grid, args.frames, quality,
                                         (b_time, b_x, b_motion), runs),
                             *ratios_note(ratios)]), flush=True)
    return common.report(problems)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
