"""Particle benchmark: physanim against Blender's built-in particle system, and the core solver's
cost per particle-step. Prints markdown tables; nothing here asserts a timing.

    tools/bench.sh [--quick] [--count N] [--frames F] [--sizes 10000,100000,1000000] [--profile]

Part 1, "compare" — one scene, one process, both simulators: ``--count`` particles emitted from
a 2 x 2 m plane at z = 2 m (facing up, 2 m/s along the normal) over the first ``--emit-frames``
frames, gravity, bouncing on a ground at z = 0 (restitution 0.5 / friction 0.3), ``--frames``
frames at 25 fps (Blender's default particle timestep is 0.04 s per frame, so both simulate the
same seconds):

* Blender: a ParticleSystem modifier (Newtonian, its default midpoint integrator, no subframes)
  and a Collision modifier on a 40 x 40 m ground mesh (damping 0.5, friction 0.3), simulated by
  stepping ``scene.frame_set(1..F)`` from an empty point cache (``--blender-method bake`` uses
  ``bpy.ops.ptcache.bake`` instead — it costs the same).
* physanim bake: the real add-on path (extension enabled, object/scene properties, saved .blend,
  ``bpy.ops.physanim.bake()``, which includes extraction and writing the cache).
* physanim core: the same scene straight through ``core.particles`` (no Blender, no cache).

Each run is checked afterwards (particle count, nobody below the ground, particles moved).

Part 2, "steady" — core solver only: N particles pre-filled high above a ground with long lives,
one warm-up frame, then ``--steady-frames`` frames of one sub-step each, per integrator, one
after another as a bake runs them (garbage collected once before them, not before each).

Part "colliders" (``--parts colliders``) — the steady particles (symplectic Euler) beside one
collider of each kind out of their reach (none, the ground below, a sphere, a box, a mesh, and
the sphere, box and mesh moving and turning as an animated object does, and twenty boxes in a
grid, still and moving), at the first two ``--sizes``: what a collider costs the particles it
is far from.

Part 3, "memory" (``--parts memory``; not run by default: it writes gigabytes) — the peak memory
of a ``--memory-count`` particle bake at the defaults for each of ``--memory-frames`` frame
counts, each in its own process (``bench/particles_memory.py``).

``--profile`` runs one more physanim bake under cProfile (after the timed runs) and prints the
hottest core and add-on functions.
"""
from __future__ import annotations

import argparse
import gc
import importlib
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench import blender_side, common, particles_compare, particles_memory  # blender_side: before any bpy
from bench.particles_compare import FPS, FRICTION, RESTITUTION


# --- part 2: steady state per particle-step -------------------------------------------------------

def steady(n: int, integrator: str, frames: int, colliders: list | None = None) -> dict:
    """``n`` particles in flight for ``frames`` frames of one sub-step; ``colliders``: the
    scene's ColliderFrames (default: the ground half-space below them)."""
    P, contact = common.core_module("particles"), common.core_module("contact")
    builder = P.ParticleModelBuilder(seed=0)
    builder.add_emitter(P.EmitterSettings(name="Filled"))
    model = builder.finalize(0)
    solver = P.ParticleSolver(model, integrator, 1)
    state = model.state(0.0)
    rng = np.random.default_rng(1)
    x = np.column_stack([rng.uniform(-10, 10, n), rng.uniform(-10, 10, n), rng.uniform(5, 50, n)])
    state.append(0, x, np.zeros((n, 3)), np.full(n, 0.1), np.zeros(n), np.full(n, 1e6),
                 np.full(n, 0.05))
    dt = 1.0 / FPS
    if colliders is None:
        colliders = [contact.ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4),
                                           RESTITUTION, FRICTION)]
    idle = P.EmitterFrame(active=False)

    def inputs(frame):
        return P.FrameInputs(frame=frame, t0=frame * dt, frame_dt=dt, emitters=[idle],
                             colliders=colliders)

    times = []
    collisions = 0
    with importlib.import_module("physanim.addon.allocator").reuse():  # as a bake runs
        solver.advance(state, inputs(0))  # warm-up (allocations, caches)
        gc.collect()  # once, before the frames: a bake's frames follow each other (a full
        # collection before each would evict the caches and time a cold start every frame)
        for frame in range(1, frames + 1):
            start = time.perf_counter()
            report = solver.advance(state, inputs(frame))
            times.append(time.perf_counter() - start)
            collisions += report.collisions
    times = np.array(times)
    return {"n": n, "integrator": integrator, "frame_ms": 1e3 * times.mean(),
            "ns_mean": 1e9 * times.mean() / n, "ns_min": 1e9 * times.min() / n,
            "collisions": collisions, "alive": state.particle_count}


def beside_colliders() -> dict:
    """One collider of each kind, 30 m beside the steady particles (out of their reach): what
    a collider costs the particles it is far from."""
    contact = common.core_module("contact")
    at = np.eye(4)
    at[:3, 3] = (30.0, 0.0, 2.0)
    u = np.linspace(-1.0, 1.0, 100)
    gx, gy = np.meshgrid(u, u)
    verts = np.column_stack([gx.ravel(), gy.ravel(), 0.1 * np.sin(3.0 * gx.ravel())])
    i = np.arange(100 * 100).reshape(100, 100)
    a, b, c, d = (i[:-1, :-1].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel(),
                  i[:-1, 1:].ravel())
    tris = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])

    # moving: 0.2 m along x and turned 0.1 rad about z over each frame (an animated object)
    c, s = np.cos(0.1), np.sin(0.1)
    moved = np.array([[c, -s, 0.0, 0.2], [s, c, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0],
                      [0.0, 0.0, 0.0, 1.0]]) @ at

    def frame(name, shape, end=at, start=at, **mesh):
        return contact.ColliderFrame(name, shape, start, end, RESTITUTION, FRICTION, **mesh)
    mesh = {"vertices0": verts, "vertices1": verts, "triangles": tris}
    rock = common.core_module("collision.shapes").sphere_mesh(1, 0.5, "rock")
    # twenty boxes 3 m apart in a 5 x 4 grid beside the particles (a scene's props)
    grid = []
    for k in range(20):
        m = at.copy()
        m[:3, 3] += (3.0 * (k % 5), 3.0 * (k // 5), 0.0)
        grid.append(m)
    return {"none": [], "ground below (half-space)": None,
            "sphere beside": [frame("Sphere", "SPHERE")], "box beside": [frame("Box", "BOX")],
            f"mesh beside ({len(tris):,} triangles)": [frame("Mesh", "MESH", **mesh)],
            "sphere moving beside": [frame("Sphere", "SPHERE", moved)],
            "box moving beside": [frame("Box", "BOX", moved)],
            "mesh moving beside": [frame("Mesh", "MESH", moved, **mesh)],
            "20 boxes beside": [frame(f"Box{k}", "BOX", m, m) for k, m in enumerate(grid)],
            "20 boxes moving beside": [frame(f"Box{k}", "BOX", moved @ np.linalg.inv(at) @ m, m)
                                       for k, m in enumerate(grid)],
            # rigid bodies' hulls as the particles meet them: one vertex array for the frame
            f"20 rocks moving beside (hull meshes, {len(rock.triangles)} triangles)": [
                frame(f"Rock{k}", "MESH", moved @ np.linalg.inv(at) @ m, m,
                      vertices0=rock.vertices, vertices1=rock.vertices,
                      triangles=rock.triangles) for k, m in enumerate(grid)]}


def collider_costs(opts: Options) -> list[str]:
    """Part "colliders": the steady particles (symplectic Euler) beside one collider of each
    kind; prints ms per frame and the cost over no collider."""
    rows, problems = [], []
    for n in opts.sizes[:2]:
        base = None
        for name, colliders in beside_colliders().items():
            row = steady(n, "SYMPLECTIC_EULER", opts.steady_frames, colliders)
            base = base or row["frame_ms"]
            rows.append((f"{n:,}", name, f"{row['frame_ms']:.2f}", f"{row['ns_mean']:.0f}",
                         f"{row['frame_ms'] / base:.2f}"))
            if row["alive"] != n or row["collisions"]:
                problems.append(f"colliders {n:,} {name}: a particle met the collider")
            gc.collect()
    print("\n".join([
        f"### Core solver beside colliders ({opts.steady_frames} frames of 1 substep, particles "
        "in flight as in the steady table; each collider out of their reach)", "",
        *common.markdown_table(("particles", "collider", "ms / frame",
                                "ns / particle-step", "x no collider"), "rlrrr", rows)]) + "\n",
          flush=True)
    return problems


# --- output ---------------------------------------------------------------------------------------

def steady_table(rows: list[dict], frames: int) -> str:
    cells = [(f"{r['n']:,}", r["integrator"], f"{r['frame_ms']:.1f}", f"{r['ns_mean']:.0f}",
              f"{r['ns_min']:.0f}") for r in rows]
    return "\n".join([
        f"### Core solver, steady state ({frames} frames of 1 substep after a warm-up; "
        "particles in the air above a half-space ground; the bake's memory reuse)", "",
        *common.markdown_table(("particles", "integrator", "ms / frame",
                                "ns / particle-step (mean)", "ns / particle-step (best)"),
                               "rlrrr", cells)])


# --- the command ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class Options:
    """What one run of the command does (``--help`` explains each)."""

    scene: particles_compare.Scene
    sizes: tuple[int, ...]
    steady_frames: int
    integrators: tuple[str, ...]
    parts: frozenset[str]  # of compare, steady, colliders, memory, profile
    blender_method: str
    no_blender: bool
    top: int
    memory_count: int = 1_000_000
    memory_frames: tuple[int, ...] = (50, 125, 250)


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--quick", action="store_true",
                    help="smoke run: 20k particles, 60 frames, steady sizes 10k and 100k")
    ap.add_argument("--count", type=int, help="particles emitted (default 100000)")
    ap.add_argument("--frames", type=int, help="frames simulated (default 250)")
    ap.add_argument("--emit-frames", type=int,
                    help="frames over which all particles are born (default min(100, 2/5 frames))")
    ap.add_argument("--sizes", help="steady-state particle counts (default 10000,100000,1000000)")
    ap.add_argument("--steady-frames", type=int, help="timed frames per steady run (default 20)")
    ap.add_argument("--integrators", default="SYMPLECTIC_EULER,RK4")
    ap.add_argument("--blender-method", choices=("frames", "bake"), default="frames",
                    help="frame_set(1..F) from an empty cache (default) or ptcache.bake")
    ap.add_argument("--parts", default="compare,steady",
                    help="comma list of: compare, steady, colliders, memory (add profile "
                         "with --profile)")
    ap.add_argument("--memory-count", type=int, default=1_000_000,
                    help="memory: particles of the bakes (default 1000000)")
    ap.add_argument("--memory-frames", default="50,125,250",
                    help="memory: the frame counts baked, each in its own process")
    ap.add_argument("--no-blender", action="store_true",
                    help="compare: skip Blender's built-in run")
    ap.add_argument("--profile", action="store_true",
                    help="also profile one extra physanim bake with cProfile")
    ap.add_argument("--top", type=int, default=15, help="rows per profile table")
    return ap


def parse_args(argv: list[str]) -> Options:
    """The command line with its defaults (``--quick`` picks smaller ones) filled in."""
    ap = _parser()
    args = ap.parse_args(argv)
    count = args.count or (20_000 if args.quick else 100_000)
    frames = args.frames or (60 if args.quick else 250)
    if frames < 2 or count < 1:
        ap.error("need --frames >= 2 and --count >= 1")
    emit = args.emit_frames or max(1, min(100, (2 * frames) // 5))
    parts = {p.strip() for p in args.parts.split(",") if p.strip()}
    if args.profile:
        parts.add("profile")
    return Options(
        scene=particles_compare.Scene(count, frames, min(emit, frames - 1)),
        sizes=tuple(common.int_list(args.sizes or ("10000,100000" if args.quick else
                                                   "10000,100000,1000000"))),
        steady_frames=args.steady_frames or (5 if args.quick else 20),
        integrators=tuple(i.strip() for i in args.integrators.split(",")),
        parts=frozenset(parts), blender_method=args.blender_method, no_blender=args.no_blender,
        top=args.top, memory_count=args.memory_count,
        memory_frames=tuple(common.int_list(args.memory_frames)))


def compare(opts: Options, folder: str) -> list[str]:
    """Part 1: the scene through Blender, the physanim bake and the core; prints the table and
    returns the runs' problems."""
    sc, runs = opts.scene, []
    if not opts.no_blender:
        runs.append(particles_compare.run_blender(sc, opts.blender_method))
        print(f"(Blender: {runs[-1].wall:.2f} s)", flush=True)
    runs.append(particles_compare.run_physanim_bake(sc, folder))
    print(f"(physanim bake at defaults: {runs[-1].wall:.2f} s)", flush=True)
    runs.append(particles_compare.run_physanim_bake(sc, folder, tuned=True))
    print(f"(physanim bake, tuned: {runs[-1].wall:.2f} s)", flush=True)
    runs.append(particles_compare.run_core(sc, particles_compare.default_substeps()))
    print(f"(physanim core: {runs[-1].wall:.2f} s)\n", flush=True)
    print(particles_compare.compare_table(runs, sc) + "\n", flush=True)
    return [p for r in runs for p in r.problems]


def steady_states(opts: Options) -> list[str]:
    """Part 2: every size with every integrator; prints the table and returns the runs that were
    not steady (a particle lost or a collision: the timings would not be per free flight)."""
    rows, problems = [], []
    for n in opts.sizes:
        for integrator in opts.integrators:
            row = steady(n, integrator, opts.steady_frames)
            rows.append(row)
            if row["alive"] != n or row["collisions"]:
                problems.append(f"steady {n:,} {row['integrator']}: {row['alive']:,} "
                                f"alive, {row['collisions']} collisions (expected {n:,}, "
                                "0: the setup is not steady)")
            gc.collect()
    print(steady_table(rows, opts.steady_frames) + "\n", flush=True)
    return problems


def run_parts(opts: Options, folder: str) -> list[str]:
    """The parts asked for, in order: compare, steady, memory, profile; returns their
    problems."""
    problems: list[str] = []
    if "compare" in opts.parts:
        problems += compare(opts, folder)
    if "steady" in opts.parts:
        problems += steady_states(opts)
    if "colliders" in opts.parts:
        problems += collider_costs(opts)
    if "memory" in opts.parts:
        rows = particles_memory.measure(opts.memory_count, list(opts.memory_frames))
        print(particles_memory.table(opts.memory_count, rows) + "\n", flush=True)
        problems += [f"memory: {r['alive']:,} alive at the end of {r['frames']} frames, "
                     f"expected {opts.memory_count:,}" for r in rows
                     if r["alive"] != opts.memory_count]
    if "profile" in opts.parts:
        print(particles_compare.profile_physanim_bake(opts.scene, folder, opts.top), flush=True)
    return problems


def main(argv: list[str]) -> int:
    """Options -> heading -> the parts, in a temp folder with the extension enabled -> report."""
    opts = parse_args(argv)

    import bpy

    print(f"# physanim particle benchmark — Blender {bpy.app.version_string}, "
          f"{common.machine()}{common.blas_threads()}\n", flush=True)
    with (tempfile.TemporaryDirectory(prefix="physanim_bench_", ignore_cleanup_errors=True)
          as folder, blender_side.extension_enabled()):
        problems = run_parts(opts, folder)
    common.print_final_load()
    return common.report(problems)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
