"""Mesh-mesh overlap benchmark: physanim's hierarchies (OBB, AABB, sphere, 18-DOP trees) against
Blender's C BVH (``mathutils.bvhtree.BVHTree.overlap``) on the same pairs of meshes, with the
seed's cost terms. Prints a markdown table; nothing here asserts a timing.

    tools/bench.sh collision [--grid 159] [--repeat 3]

Scenes: two wavy grids of ~50,000 triangles each (159 x 159 vertices), B rotated slightly and
1 mm above A ("close parallel proximity", thousands of crossing pairs), and the same pair 1 m
apart ("far apart"). Every method must return the same pairs as Blender (checked).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from tools import blender_env  # noqa: E402  (sets BLENDER_USER_RESOURCES before bpy)

import bpy  # noqa: E402,F401  (mathutils comes with it)
from mathutils.bvhtree import BVHTree  # noqa: E402

KINDS = ("obb", "aabb", "sphere", "kdop18")


def _best(fn, repeat: int):
    best, out = np.inf, None
    for _ in range(repeat):
        start = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - start)
    return best, out


def _rotation_z(angle: float, offset) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:3, 3] = offset
    return m


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", type=int, default=159)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    module = blender_env.enable_extension()
    try:
        from importlib import import_module
        collision = import_module(module.__name__ + ".core.collision")
        shapes = import_module(module.__name__ + ".core.collision.shapes")
        mesh = shapes.grid_mesh(args.grid, size=2.0, amplitude=0.05, name="wavy")
        scenes = {"close parallel (1 mm)": _rotation_z(0.01, (0.003, 0.002, 0.001)),
                  "far apart (1 m)": _rotation_z(0.01, (0.0, 0.0, 1.0))}
        rows, problems = [], []
        builds = {}
        for kind in KINDS:
            builds[kind] = _best(lambda kind=kind: collision.build_bvh(mesh, kind, "topdown"), 1)
        verts, tris = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
        for label, mb in scenes.items():
            world_b = verts @ mb[:3, :3].T + mb[:3, 3]
            start = time.perf_counter()
            tree_a = BVHTree.FromPolygons(verts.tolist(), tris.tolist(), all_triangles=True)
            tree_b = BVHTree.FromPolygons(world_b.tolist(), tris.tolist(), all_triangles=True)
            blender_build = (time.perf_counter() - start) / 2
            blender_time, theirs = _best(lambda: tree_a.overlap(tree_b), args.repeat)
            theirs = sorted(theirs)
            rows.append((label, "Blender BVHTree (C)", blender_build, blender_time, len(theirs),
                         "—", "—", "—"))
            for kind in KINDS:
                build_time, tree = builds[kind]
                took, ours = _best(lambda tree=tree: collision.collision_determination(
                    tree, tree, None, mb), args.repeat)
                pairs = [tuple(p) for p in ours.pairs.tolist()]
                if pairs != theirs:
                    problems.append(f"{label}, {kind}: {len(pairs)} pairs, Blender {len(theirs)}")
                rows.append((label, f"physanim {kind} tree", build_time, took, len(pairs),
                             ours.n_v, ours.n_p, ours.n_u))
    finally:
        blender_env.disable_extension()
    print(f"\n### Mesh-mesh overlap: two wavy grids of {len(tris):,} triangles each\n")
    print("| scene | method | build (s) | overlap (s) | pairs | n_v | n_p | n_u | x Blender |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    blender = {}
    for label, method, build, took, pairs, n_v, n_p, n_u in rows:
        if method.startswith("Blender"):
            blender[label] = took
        ratio = took / blender[label] if blender[label] > 0 else float("inf")
        print(f"| {label} | {method} | {build:.3f} | {took:.4f} | {pairs:,} | {n_v} | {n_p} | "
              f"{n_u} | {ratio:.1f} |")
    for p in problems:
        print("MISMATCH:", p)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
