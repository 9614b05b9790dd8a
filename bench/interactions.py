"""Interactions among particles: the cost of one force evaluation of mutual gravity (Barnes-Hut)
and Lennard-Jones as the particle count grows, and the tree code's error against the exact sum
for each opening angle. Prints markdown tables; nothing here asserts a timing. Needs only numpy:

    python bench/interactions.py [--quick] [--sizes 10000,100000,1000000] [--theta 0.5]

Scenes: gravity on a Gaussian ball of unit masses (softening 0.01 of its radius); Lennard-Jones
on a liquid-like cube (particles on a jittered lattice at the potential's minimum, sigma 0.1 m,
cutoff 2.5 sigma: about 60 neighbours each). Blender has neither force among its particles
(its SPH fluid is the only interaction; the particle-collision benchmark compares against
it), so these tables are per-step costs, not ratios.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench import common


def gravity_rows(sizes: list[int], theta: float) -> list[list[str]]:
    bh = common.core_module("forces.barnes_hut")
    rows = []
    for n in sizes:
        rng = np.random.default_rng(1)
        x = rng.normal(size=(n, 3))
        m = np.ones(n)
        tree_time, tree = common.best_of(lambda x=x, m=m: bh.Octree(x, m), 1)
        work = _interactions(bh, tree, theta)
        _, wall, _ = common.timed(lambda x=x, m=m: bh.accelerations(x, m, 1.0, 0.01, theta))
        rows.append([f"{n:,}", f"{1000 * wall:,.0f}", f"{1e6 * wall / n:.1f}",
                     f"{work / n:,.0f}", f"{1000 * tree_time:,.0f}"])
    return rows


def _interactions(bh, tree, theta: float) -> int:
    """The point-source interactions of one evaluation: the traversal taken GROUP_CHUNK groups
    at a time, fewer where its frontier would outgrow its limit, as the evaluation takes it
    (all at once it would)."""
    work, done, size, count = 0, 0, bh.GROUP_CHUNK, tree.node_count[tree.groups]
    while done < len(tree.groups):
        chunk = np.arange(done, min(done + size, len(tree.groups)))
        try:
            (far_g, _), (near_g, near_l) = tree.interactions(theta, chunk)
        except bh._FrontierFull:  # (its frontier's limit: fewer groups at once)
            if size == 1:
                raise
            size = max(1, size // 8)
            continue
        work += int(count[far_g].sum() + (count[near_g] * tree.node_count[near_l]).sum())
        done += len(chunk)
    return work


def error_rows(n: int, thetas: list[float]) -> list[list[str]]:
    bh = common.core_module("forces.barnes_hut")
    rng = np.random.default_rng(2)
    x = rng.normal(size=(n, 3))
    m = rng.uniform(0.5, 1.5, n)
    exact_time, exact = common.best_of(lambda: bh.exact_accelerations(x, m, 1.0, 0.01), 1)
    rows = [["0 (exact sum)", "0", "0", "0", f"{1000 * exact_time:,.0f}"]]
    tree = bh.Octree(x, m)
    for theta in thetas:
        wall, a = common.best_of(lambda theta=theta: tree.accelerations(1.0, 0.01, theta), 1)
        rel = np.linalg.norm(a - exact, axis=1) / np.linalg.norm(exact, axis=1)
        rms = math.sqrt(((a - exact) ** 2).sum() / (exact ** 2).sum())
        rows.append([f"{theta:g}", f"{100 * rms:.3f}", f"{100 * np.median(rel):.3f}",
                     f"{100 * np.percentile(rel, 99):.2f}", f"{1000 * wall:,.0f}"])
    return rows


def lennard_jones_rows(sizes: list[int]) -> list[list[str]]:
    interactions = common.core_module("forces.interactions")
    fields = common.core_module("forces.fields")
    lj = interactions.LennardJones("Bench", 0.1, 0.002, 0.25)
    rows = []
    for n in sizes:
        side = round(n ** (1 / 3))
        k = np.arange(side) * lj.minimum
        grid = np.stack(np.meshgrid(k, k, k), axis=-1).reshape(-1, 3)
        rng = np.random.default_rng(3)
        x = grid + rng.uniform(-0.01, 0.01, grid.shape)
        view = fields.ParticleView(x, np.zeros_like(x), np.full(len(x), 0.1), 0.0)
        force = lj.bind(np.zeros(len(x), np.int32))
        f = np.zeros_like(x)
        _, wall, _ = common.timed(lambda force=force, view=view, f=f: force.apply(view, f))
        pairs = len(common.core_module("collision.neighbours").neighbour_pairs(x, lj.cutoff)[0])
        rows.append([f"{len(x):,}", f"{1000 * wall:,.0f}", f"{1e6 * wall / len(x):.2f}",
                     f"{2 * pairs / len(x):.0f}"])
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="small sizes only")
    parser.add_argument("--sizes", type=common.int_list, default=None)
    parser.add_argument("--theta", type=float, default=0.5)
    args = parser.parse_args(argv)
    sizes = args.sizes or ([2000, 10000] if args.quick else [10_000, 100_000, 1_000_000])
    print(f"# Interactions among particles ({common.machine()})\n")
    print(f"## Mutual gravity, Barnes-Hut at theta {args.theta:g}: one force evaluation\n")
    print("\n".join(common.markdown_table(
        ["bodies", "ms", "µs per body", "interactions per body", "tree build ms"], "lrrrr",
        gravity_rows(sizes, args.theta))))
    n_err = 3000 if args.quick else 20_000
    print(f"\n## Barnes-Hut error against the exact sum ({n_err:,} bodies, Gaussian ball)\n")
    print("\n".join(common.markdown_table(
        ["theta", "RMS error %", "median %", "99th percentile %", "ms"], "lrrrr",
        error_rows(n_err, [0.3, 0.5, 0.7, 1.0]))))
    print("\n## Lennard-Jones (sigma 0.1 m, cutoff 2.5 sigma, a liquid): one force evaluation\n")
    print("\n".join(common.markdown_table(
        ["particles", "ms", "µs per particle", "neighbours per particle"], "lrrr",
        lennard_jones_rows(sizes))))
    common.print_final_load()
    return 0


if __name__ == "__main__":
    sys.exit(main())
