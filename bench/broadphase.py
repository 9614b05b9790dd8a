"""Broad-phase benchmark: overlapping pairs per second of every broad phase on moving boxes, sweep
and prune with and without temporal coherence, and the two box policies. Prints markdown
tables; nothing here asserts a timing. Needs only numpy (no Blender):

    python bench/broadphase.py [--quick] [--sizes 1000,10000,100000] [--frames 20] [--seed 0]

Scene: n boxes with half sizes uniform in [0.25, 0.75] m per axis whose centres take a random
walk (normal steps of ``--step`` m per axis per frame, reflected at the walls) inside a cube of
side 2 (n / 4)^(1/3) m, so a box overlaps about 4 others. Frame 0 is a warm-up (a coherent sweep
sorts from scratch there); frames 1..F are timed, each call on its own. Every method must return
the same pairs as the first one on every frame, or the run reports a failed sanity check.

Tables:

1. Each broad phase: ms per frame, overlapping pairs per second (pairs per frame / seconds per
   frame), candidates tested per frame. AllPairs runs up to ``--all-pairs-max`` boxes.
2. Sweep and prune, sort step alone (the two paths ``SweepAndPrune`` takes: from scratch, or
   re-sorting last frame's order), on the x endpoints: ms per frame and the exact number of
   swaps an insertion sort makes (counted outside the timing) against a fresh insertion sort.
3. Box policies on spinning rods: fixed-size cubes (bounding sphere, never recomputed) against
   dynamic AABBs (recomputed from each rod's rotation every frame).
"""
from __future__ import annotations

import argparse
import hashlib
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench import common

NEIGHBOURS = 4.0  # expected overlapping neighbours per box
HALF_MIN, HALF_MAX = 0.25, 0.75  # [m] box half sizes


def walk(n: int, frames: int, step: float, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Boxes (lo, hi) of frames 0..frames of the random walk."""
    rng = np.random.default_rng(seed)
    side = 2.0 * (n / NEIGHBOURS) ** (1 / 3)
    centre = rng.uniform(0, side, (n, 3))
    half = rng.uniform(HALF_MIN, HALF_MAX, (n, 3))
    out = []
    for _ in range(frames + 1):
        out.append((centre - half, centre + half))
        centre = centre + rng.normal(0, step, (n, 3))
        centre = side - np.abs(side - np.abs(centre))  # reflect at 0 and at side
    return out


def methods(bp, n: int, all_pairs_max: int):
    rows = []
    if n <= all_pairs_max:
        rows.append(("AllPairs", bp.AllPairs()))
    rows += [
        ("SAP x, coherent", bp.SweepAndPrune(1, coherence=True)),
        ("SAP x, fresh sort", bp.SweepAndPrune(1, coherence=False)),
        ("SAP xyz, coherent", bp.SweepAndPrune(3, coherence=True)),
        ("SAP xyz, fresh sort", bp.SweepAndPrune(3, coherence=False)),
        ("UniformGrid (auto cell)", bp.UniformGrid()),
        ("Octree (depth 10, leaf 8)", bp.Octree()),
    ]
    return rows


def _digest(pairs: np.ndarray) -> str:
    return hashlib.blake2b(pairs.tobytes(), digest_size=16).hexdigest()


def run_methods(bp, n: int, frames: list, all_pairs_max: int, problems: list[str]) -> list[dict]:
    rows, reference = [], None
    for name, method in methods(bp, n, all_pairs_max):
        seconds, pairs, candidates, digests = 0.0, 0, 0, []
        for f, (lo, hi) in enumerate(frames):
            start = time.perf_counter()
            found = method.pairs(lo, hi)
            elapsed = time.perf_counter() - start
            digests.append(_digest(found))
            if f:  # frame 0 is the warm-up
                seconds += elapsed
                pairs += len(found)
                candidates += method.last_stats.candidate_count
        timed = len(frames) - 1
        if reference is None:
            reference = (name, digests)
        elif digests != reference[1]:
            problems.append(f"{n:,} boxes: {name} returned other pairs than {reference[0]}")
        rows.append({"n": n, "name": name, "ms": 1e3 * seconds / timed, "pairs": pairs / timed,
                     "candidates": candidates / timed, "rate": pairs / seconds})
        print(f"({n:,} boxes, {name}: {1e3 * seconds / timed:.1f} ms/frame)", flush=True)
    return rows


def methods_table(rows: list[dict], timed: int) -> str:
    cells = [(f"{r['n']:,}", r["name"], f"{r['ms']:.1f}", f"{r['rate']:,.0f}",
              f"{r['pairs']:,.0f}", f"{r['candidates']:,.0f}") for r in rows]
    return "\n".join([
        (f"Broad phases on moving boxes ({timed} timed frames, about {NEIGHBOURS:g} "
         "neighbours per box):"), "",
        *common.markdown_table(("boxes", "method", "ms/frame", "pairs/s", "pairs/frame",
                                "candidates/frame"), "rlrrrr", cells)])


def sort_row(bp, n: int, frames: list) -> dict:
    """The endpoint sort alone, through SweepAndPrune's own two paths, on x."""
    timing = bp.SweepAndPrune(1)
    counting = bp.SweepAndPrune(1, count_swaps=True)
    values = [np.concatenate([lo[:, 0], hi[:, 0]]) for lo, hi in frames]
    fresh_s = coherent_s = 0.0
    order = timing._sort(values[0])[0]
    for v in values[1:]:
        start = time.perf_counter()
        timing._sort(v)
        fresh_s += time.perf_counter() - start
        start = time.perf_counter()
        order = timing._resort(v, order)[0]
        coherent_s += time.perf_counter() - start
    swaps = fresh_swaps = moved = 0
    order = counting._sort(values[0])[0]
    for v in values[1:]:
        fresh_swaps += counting._sort(v)[2]
        order, displacement, swapped = counting._resort(v, order)
        swaps += swapped
        moved += displacement
    timed = len(values) - 1
    return {"n": n, "fresh_ms": 1e3 * fresh_s / timed, "coherent_ms": 1e3 * coherent_s / timed,
            "swaps": swaps / timed, "fresh_swaps": fresh_swaps / timed, "moved": moved / timed}


def sort_table(rows: list[dict], step: float) -> str:
    cells = [(f"{r['n']:,}", f"{r['fresh_ms']:.2f}", f"{r['coherent_ms']:.2f}",
              f"{r['fresh_ms'] / r['coherent_ms']:.1f}x", f"{r['swaps']:,.0f}",
              f"{r['fresh_swaps']:,.0f}", f"{r['moved']:,.0f}") for r in rows]
    return "\n".join([
        (f"Sweep and prune, sorting the 2n x endpoints alone (random walk, step {step:g} m "
         "per axis per frame):"), "",
        *common.markdown_table(("boxes", "fresh sort ms", "coherent re-sort ms", "speed-up",
                                "swaps/frame coherent", "swaps of a fresh insertion sort",
                                "endpoint displacement/frame"), "rrrrrrr", cells)])


def _rotations(rng: np.random.Generator, n: int, angle: float | None = None) -> np.ndarray:
    """(n, 3, 3) rotations about random axes; random angles unless ``angle`` [rad] is given."""
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    theta = rng.uniform(0, np.pi, n) if angle is None else np.full(n, angle)
    k = np.zeros((n, 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    k -= np.swapaxes(k, 1, 2)
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    return np.eye(3) + s * k + (1 - c) * (k @ k)


def policy_rows(bp, n: int, frames: int, step: float, seed: int, problems) -> list[dict]:
    """Spinning rods (half sizes 0.8 x 0.15 x 0.15 m, 0.1 rad per frame) under both policies."""
    rng = np.random.default_rng(seed + 1)
    half = np.tile([0.8, 0.15, 0.15], (n, 1))
    radius = np.linalg.norm(half, axis=1)
    side = 2.0 * (n / NEIGHBOURS) ** (1 / 3)
    centre = rng.uniform(0, side, (n, 3))
    rotation = _rotations(rng, n)
    spin = _rotations(rng, n, 0.1)
    poses = []
    for _ in range(frames + 1):
        poses.append((centre, rotation))
        centre = side - np.abs(side - np.abs(centre + rng.normal(0, step, (n, 3))))
        rotation = spin @ rotation
    policies = {
        "fixed cubes": lambda c, r: bp.cube_boxes(c, radius),
        "dynamic AABBs": lambda c, r: bp.aabb_of_oriented_boxes(c, r, half),
    }
    rows = []
    for method_name, make in (("SAP x, coherent", lambda: bp.SweepAndPrune(1)),
                              ("UniformGrid (auto cell)", bp.UniformGrid)):
        found_by_policy = {}
        for policy, boxes in policies.items():
            method, box_s, pair_s, pairs, candidates, found = make(), 0.0, 0.0, 0, 0, []
            for f, (c, r) in enumerate(poses):
                start = time.perf_counter()
                lo, hi = boxes(c, r)
                middle = time.perf_counter()
                result = method.pairs(lo, hi)
                end = time.perf_counter()
                found.append(result)
                if f:
                    box_s += middle - start
                    pair_s += end - middle
                    pairs += len(result)
                    candidates += method.last_stats.candidate_count
            found_by_policy[policy] = found
            rows.append({"n": n, "method": method_name, "policy": policy,
                         "box_ms": 1e3 * box_s / frames, "ms": 1e3 * pair_s / frames,
                         "pairs": pairs / frames, "candidates": candidates / frames})
        for tight, loose in zip(found_by_policy["dynamic AABBs"], found_by_policy["fixed cubes"]):
            if not set(map(tuple, tight)) <= set(map(tuple, loose)):
                problems.append(f"{method_name}: a dynamic-AABB pair is missing from the cubes'")
    return rows


def policy_table(rows: list[dict]) -> str:
    n = rows[0]["n"] if rows else 0
    cells = [(r["method"], r["policy"], f"{r['box_ms']:.2f}", f"{r['ms']:.1f}",
              f"{r['pairs']:,.0f}", f"{r['candidates']:,.0f}") for r in rows]
    return "\n".join([
        (f"Box policies: {n:,} spinning rods (0.8 x 0.15 x 0.15 m half sizes, 0.1 rad per "
         "frame); the cube of a rod is its bounding sphere's:"), "",
        *common.markdown_table(("method", "policy", "box update ms/frame",
                                "broad phase ms/frame", "pairs/frame", "candidates/frame"),
                               "llrrrr", cells)])


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--quick", action="store_true", help="smoke run: 1k and 10k boxes, 5 frames")
    ap.add_argument("--sizes", help="box counts (default 1000,10000,100000)")
    ap.add_argument("--frames", type=int, help="timed frames (default 20)")
    ap.add_argument("--step", type=float, default=0.02,
                    help="random-walk step per axis per frame [m] (default 0.02)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--all-pairs-max", type=int, default=10_000,
                    help="largest box count AllPairs runs on (default 10000)")
    ap.add_argument("--policy-boxes", type=int, help="rods in the policy table (default 10000)")
    args = ap.parse_args(argv)
    sizes = common.int_list(args.sizes or ("1000,10000" if args.quick else "1000,10000,100000"))
    frames = args.frames or (5 if args.quick else 20)
    policy_boxes = args.policy_boxes or (1000 if args.quick else 10_000)
    if frames < 1 or min(sizes) < 2:
        ap.error("need --frames >= 1 and box counts >= 2")
    bp = common.core_module("collision.broadphase")

    print(f"# physanim broad-phase benchmark — {common.machine()}\n", flush=True)
    problems: list[str] = []
    rows, sorts = [], []
    for n in sizes:
        scene = walk(n, frames, args.step, args.seed)
        rows += run_methods(bp, n, scene, args.all_pairs_max, problems)
        sorts.append(sort_row(bp, n, scene))
    policies = policy_rows(bp, policy_boxes, frames, args.step, args.seed, problems)
    print()
    print(methods_table(rows, frames) + "\n")
    print(sort_table(sorts, args.step) + "\n")
    print(policy_table(policies) + "\n")
    common.print_final_load()
    return common.report(problems)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
