"""Mesh-mesh overlap benchmark: physanim's hierarchies (OBB, AABB, sphere, 18-DOP trees) against
Blender's C BVH (``mathutils.bvhtree.BVHTree.overlap``) on the same pairs of meshes, with the
seed's cost terms. Prints a markdown table; nothing here asserts a timing.

    tools/bench.sh collision [--grid 159] [--repeat 3] [--particles 100000]
                             [--particle-frames 24] [--particle-substeps 2]

Scenes: two wavy grids of ~50,000 triangles each (159 x 159 vertices), B rotated slightly and
1 mm above A ("close parallel proximity", thousands of crossing pairs), and the same pair 1 m
apart ("far apart"). Every method must return the same pairs as Blender (checked). The trees
are descended both at once (``descend="both"``: the meshes are the same size); ``obb6`` is the
OBB tree with the seed's 6-axis separating test (faces only: it may let a pair of boxes through
that an edge axis would separate, and the tree then just descends further).

Then particles on a mesh collider (core solver only): rain onto a wavy 100k-triangle mesh, and
the same rain onto the analytic ground in the same run, the mesh's cost printed as a multiple
of the ground's (issue 12: at most 10 x), at the emitters' default 2 sub-steps.
"""
from __future__ import annotations

import argparse
import sys
import time
from importlib import import_module
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench import blender_side, common  # blender_side first: it sets up Blender before bpy
import bpy  # noqa: F401  (mathutils comes with it)
from mathutils.bvhtree import BVHTree

KINDS = ("obb", "obb6", "aabb", "sphere", "kdop18")
DESCEND = "both"  # two trees of the same size: split both nodes of a pair at once


def _rotation_z(angle: float, offset) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:3, 3] = offset
    return m


def particles_vs_mesh(module_name: str, particles: int, grid: int, frames: int,
                      analytic: bool = False, substeps: int = 2) -> tuple:
    """Core solver only: ``particles`` falling onto a wavy ``grid`` x ``grid`` mesh collider
    (``substeps`` per frame: 2 is the emitters' default), or with ``analytic`` onto a flat
    ground (a HALF_SPACE at the mesh's mean height) in the same way; returns (seconds,
    particle-steps per second, triangles: 0 for the ground)."""
    shapes = import_module(module_name + ".core.collision.shapes")
    P = import_module(module_name + ".core.particles")
    contact = import_module(module_name + ".core.contact")
    mesh = shapes.grid_mesh(grid, size=20.0, amplitude=0.3, name="ground")
    verts = np.asarray(mesh.vertices) - [10.0, 10.0, 0.0]
    tris = np.asarray(mesh.triangles)
    builder = P.ParticleModelBuilder(seed=1)
    builder.add_emitter(P.EmitterSettings("Rain"))
    model = builder.finalize()
    state = model.state()
    rng = np.random.default_rng(0)
    x = np.column_stack([rng.uniform(-9.5, 9.5, (particles, 2)), rng.uniform(0.5, 3.0, particles)])
    state.append(0, x, np.zeros_like(x), np.ones(particles), np.zeros(particles),
                 np.full(particles, 1e9), np.full(particles, 0.02))
    if analytic:
        ground = contact.ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4),
                                       restitution=0.3, friction=0.4)
    else:
        ground = contact.ColliderFrame("Ground", "MESH", np.eye(4), np.eye(4), restitution=0.3,
                                       friction=0.4, vertices0=verts, vertices1=verts,
                                       triangles=tris)
    solver = P.ParticleSolver(model, "SYMPLECTIC_EULER", substeps)
    start = time.perf_counter()
    for f in range(frames):
        solver.advance(state, P.FrameInputs(f, f / 24, 1 / 24,
                                            emitters=[P.EmitterFrame(active=False)],
                                            colliders=[ground]))
    took = time.perf_counter() - start
    return took, particles * frames * substeps / took, 0 if analytic else len(tris)


def overlap_rows(module_name: str, grid: int, repeat: int) -> tuple[list[tuple], list[str], int]:
    """Every scene through Blender's BVHTree and each physanim tree kind (the pairs compared with
    Blender's); returns (table rows, mismatches, triangles per mesh)."""
    collision = import_module(module_name + ".core.collision")
    shapes = import_module(module_name + ".core.collision.shapes")
    mesh = shapes.grid_mesh(grid, size=2.0, amplitude=0.05, name="wavy")
    scenes = {"close parallel (1 mm)": _rotation_z(0.01, (0.003, 0.002, 0.001)),
              "far apart (1 m)": _rotation_z(0.01, (0.0, 0.0, 1.0))}
    rows, problems = [], []
    builds = {}
    for kind in KINDS:
        builds[kind] = common.best_of(
            lambda kind=kind: collision.build_bvh(mesh, kind, "topdown"), 1)
    verts, tris = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    for label, mb in scenes.items():
        world_b = verts @ mb[:3, :3].T + mb[:3, 3]
        start = time.perf_counter()
        tree_a = BVHTree.FromPolygons(verts.tolist(), tris.tolist(), all_triangles=True)
        tree_b = BVHTree.FromPolygons(world_b.tolist(), tris.tolist(), all_triangles=True)
        blender_build = (time.perf_counter() - start) / 2
        blender_time, theirs = common.best_of(lambda a=tree_a, b=tree_b: a.overlap(b), repeat)
        theirs = sorted(theirs)
        rows.append((label, "Blender BVHTree (C)", blender_build, blender_time, len(theirs),
                     "—", "—", "—"))
        for kind in KINDS:
            build_time, tree = builds[kind]
            took, ours = common.best_of(lambda tree=tree, mb=mb: collision.collision_determination(
                tree, tree, None, mb, descend=DESCEND), repeat)
            pairs = [tuple(p) for p in ours.pairs.tolist()]
            if pairs != theirs:
                problems.append(f"{label}, {kind}: {len(pairs)} pairs, Blender {len(theirs)}")
            rows.append((label, f"physanim {kind} tree", build_time, took, len(pairs),
                         ours.n_v, ours.n_p, ours.n_u))
    return rows, problems, len(tris)


def overlap_table(rows: list[tuple], triangles: int) -> str:
    """Each row with its time as a multiple of Blender's in the same scene."""
    cells, blender = [], {}
    for label, method, build, took, pairs, n_v, n_p, n_u in rows:
        if method.startswith("Blender"):
            blender[label] = took
        ratio = took / blender[label] if blender[label] > 0 else float("inf")
        cells.append((label, method, f"{build:.3f}", f"{took:.4f}", f"{pairs:,}", n_v, n_p, n_u,
                      f"{ratio:.1f}"))
    return "\n".join([
        f"\n### Mesh-mesh overlap: two wavy grids of {triangles:,} triangles each\n",
        *common.markdown_table(("scene", "method", "build (s)", "overlap (s)", "pairs", "n_v",
                                "n_p", "n_u", "x Blender"), "llrrrrrrr", cells)])


def rain_table(particles: int, frames: int, substeps: int, rain: tuple, flat: tuple) -> str:
    """The particles-vs-mesh run ``rain`` and the same rain on the analytic ground ``flat``
    (:func:`particles_vs_mesh`'s results), with the cost per particle-step of the mesh as a
    multiple of the ground's."""
    rows = [(name, f"{particles:,}", f"{tris:,}" if tris else "—", frames, f"{took:.2f}",
             f"{rate:,.0f}", f"{flat[1] / rate:.1f}")
            for name, (took, rate, tris) in (("wavy mesh collider", rain),
                                             ("analytic ground (HALF_SPACE)", flat))]
    return "\n".join([
        f"\n### Particles vs a mesh collider (core, {substeps} sub-steps per frame)\n",
        *common.markdown_table(("collider", "particles", "triangles", "frames", "time (s)",
                                "particle-steps / s", "x ground's cost"), "lrrrrrr", rows)])


def main(argv: list[str]) -> int:
    """Overlaps, then particles on a mesh, with the extension enabled -> tables -> mismatches."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", type=int, default=159)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--particles", type=int, default=100_000)
    ap.add_argument("--particle-grid", type=int, default=225,
                    help="225 x 225 vertices: 100k triangles")
    ap.add_argument("--particle-frames", type=int, default=24)
    ap.add_argument("--particle-substeps", type=int, default=2, help="2: the default")
    args = ap.parse_args(argv)
    with blender_side.extension_enabled() as module:
        rows, problems, triangles = overlap_rows(module.__name__, args.grid, args.repeat)
        rain = particles_vs_mesh(module.__name__, args.particles, args.particle_grid,
                                 args.particle_frames, substeps=args.particle_substeps)
        flat = particles_vs_mesh(module.__name__, args.particles, args.particle_grid,
                                 args.particle_frames, analytic=True,
                                 substeps=args.particle_substeps)
    print(overlap_table(rows, triangles))
    print(rain_table(args.particles, args.particle_frames, args.particle_substeps, rain, flat))
    return common.report(problems, "MISMATCH:")


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
