"""Heap benchmark: grains poured into a heap by Particle Collisions, measured once at rest — how
deep grains sit in each other, whether the heap has stopped, how steep it stands for each
friction — and what the pour cost. Prints a markdown table; nothing here asserts. Needs only
numpy:

    tools/bench.sh heap [--grains 10000] [--frames 200] [--friction 0.2,0.6] [--seeds 0,1]

"Deepest at rest" is the deepest overlap between two grains that are both at rest (slower than
1 cm/s); "deepest" takes every pair, grains still sliding down the flank among them, and
"grains moving" counts those at 1 cm/s or faster.

The scene (the core heap test's, at a larger size): grains of 1 cm radius and 1 g poured
over 40 frames from a 6 cm hopper 30 cm up, a loose batch each frame overlapping one another,
onto a ground with the same friction; symplectic Euler, 4 sub-steps, 24 fps, restitution 0.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench import common

RADIUS = 0.01  # [m]
POUR = 40  # frames
DT = 1.0 / 24.0
AT_REST = 0.01  # [m/s]: a grain slower than this is at rest (a sliding one is not)


def pour(grains: int, friction: float, frames: int, seed: int = 0):
    """The state after ``frames`` frames of pouring ``grains`` (then settling); ``seed`` draws
    where each grain starts."""
    particles = common.core_module("particles")
    contact = common.core_module("contact")
    pairs = common.core_module("particles.pair_collisions")
    builder = particles.ParticleModelBuilder(0)
    builder.add_emitter(particles.EmitterSettings("Sand"))
    model = builder.finalize()
    state = model.state()
    ground = contact.ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4),
                                   restitution=0.0, friction=friction, thickness=RADIUS)
    solver = particles.ParticleSolver(model, "SYMPLECTIC_EULER", 4)
    collisions = [pairs.ParticleCollisions("Sand", restitution=0.0, friction=friction)]
    idle = [particles.EmitterFrame(active=False)]
    rng = np.random.default_rng(seed)
    per = grains // POUR
    for f in range(frames):
        if f < POUR:
            angle, far = rng.uniform(0, 2 * np.pi, per), 0.06 * np.sqrt(rng.uniform(0, 1, per))
            x = np.stack([far * np.cos(angle), far * np.sin(angle),
                          0.3 + rng.uniform(0.0, 0.15, per)], axis=1)
            v = np.tile([0.0, 0.0, -0.5], (per, 1))
            state.append(0, x, v, np.full(per, 0.001), np.zeros(per), np.full(per, 1e9),
                         np.full(per, RADIUS))
        solver.advance(state, particles.FrameInputs(
            frame=f, t0=f * DT, frame_dt=DT, gravity=(0.0, 0.0, -9.81), emitters=idle,
            colliders=[ground], collisions=collisions))
    return state


def repose_angle(x: np.ndarray) -> float:
    """The heap's slope [deg]: the grains in 20 rings about its centre, each ring as many grains,
    the height of each ring's surface (its 90th percentile), a line through the rings outside
    the highest one whose surface is between 20 and 80 % of its height. (The highest grain in
    each of 15 rings of equal width, as before, read 34 and 64 degrees for two pours of the
    same friction: the pour leaves a flat, uneven top, and where the innermost ring's highest
    grain was just under 80 % of the peak it joined the flank's line.)"""
    far = np.linalg.norm(x[:, :2] - np.median(x[:, :2], axis=0), axis=1)
    rings = np.array_split(np.argsort(far), 20)
    centre = np.array([far[r].mean() for r in rings])
    top = np.array([np.percentile(x[r, 2], 90) for r in rings])
    flank = (top > 0.2 * top.max()) & (top < 0.8 * top.max()) & \
        (np.arange(len(top)) > np.argmax(top))
    return float(np.degrees(np.arctan(-np.polyfit(centre[flank], top[flank], 1)[0])))


def row(grains: int, friction: float, frames: int, seed: int) -> list[str]:
    start = time.perf_counter()
    state = pour(grains, friction, frames, seed)
    took = time.perf_counter() - start
    x = state.particle_x
    neighbours = common.core_module("collision.neighbours")
    i, j = neighbours.neighbour_pairs(x, 2 * RADIUS)
    overlap = (2 * RADIUS - np.linalg.norm(x[i] - x[j], axis=1)) / RADIUS
    speed = np.linalg.norm(state.particle_v, axis=1)
    still = (speed[i] < AT_REST) & (speed[j] < AT_REST)
    return [f"{len(x):,}", f"{friction:g}", str(seed), str(frames),
            f"{100 * overlap[still].max(initial=0.0):.2f}", f"{100 * overlap.max():.2f}",
            f"{100 * np.percentile(overlap, 99):.2f}", f"{int((overlap > 0.01).sum())} of "
            f"{len(overlap):,}", f"{int((speed >= AT_REST).sum())}",
            f"{1000 * np.median(speed):.2f}", f"{repose_angle(x):.0f}", f"{took:.0f}"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grains", type=int, default=10_000)
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--friction", default="0.2,0.6")
    ap.add_argument("--seeds", default="0", help="pours drawn from these seeds, e.g. 0,1,2")
    args = ap.parse_args(argv)
    rows = [row(args.grains, float(mu), args.frames, int(seed))
            for mu in args.friction.split(",") for seed in args.seeds.split(",")]
    print(f"\n### A poured heap at rest: {args.grains:,} grains, {args.frames} frames\n")
    print("\n".join(common.markdown_table(
        ("grains", "friction", "seed", "frames", "deepest at rest (% r)", "deepest (% r)",
         "99th pct (% r)", "pairs over 1 % r", "grains moving", "median speed (mm/s)",
         "repose (deg)", "time (s)"), "rrrrrrrrrrrr", rows)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
