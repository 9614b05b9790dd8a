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
one warm-up frame, then ``--steady-frames`` frames of one sub-step each, per integrator.

``--profile`` runs one more physanim bake under cProfile (after the timed runs) and prints the
hottest core and add-on functions.
"""
from __future__ import annotations

import argparse
import contextlib
import cProfile
import gc
import importlib.util
import io
import os
import platform
import pstats
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from tools import blender_env  # noqa: E402  (sets BLENDER_USER_RESOURCES before bpy)

FPS = 25  # Blender's particle timestep defaults to 0.04 s/frame: 25 fps makes both agree
EMITTER_Z = 2.0  # [m] height of the emitting plane
SPEED = 2.0  # [m/s] initial speed along the plane's normal
RESTITUTION, FRICTION = 0.5, 0.3
GROUND_TOLERANCE = 1e-3  # [m] a particle lower than this below z = 0 went through the ground


# --- the physanim core, imported from the source tree without Blender -------------------------

def _core():
    """``physanim.core.particles`` of this checkout, registered by path as ``physanim``."""
    if "physanim" not in sys.modules:
        spec = importlib.util.spec_from_file_location(
            "physanim", ROOT / "__init__.py", submodule_search_locations=[str(ROOT)])
        module = importlib.util.module_from_spec(spec)
        sys.modules["physanim"] = module
        spec.loader.exec_module(module)
    import physanim.core.particles as particles
    return particles


@dataclass
class Scene:
    """The compared scene, in frames of FPS."""

    count: int
    frames: int  # last simulated frame; the run covers frames 1..frames
    emit_frames: int  # births over the intervals [1, 1 + emit_frames)

    @property
    def lifetime(self) -> int:  # [frames]: nobody dies during the run
        return self.frames + 50

    @property
    def rate(self) -> float:  # births per frame
        return self.count / self.emit_frames


@dataclass
class Run:
    name: str
    wall: float  # [s]
    cpu: float  # [s] process CPU time (Blender's particle code may use several threads)
    particles: int
    problems: list[str]
    note: str = ""


def _timed(fn):
    gc.collect()
    wall, cpu = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - wall, time.process_time() - cpu


def check_points(label: str, z: np.ndarray, expected: int) -> list[str]:
    """Sanity checks on the final particle heights: all there, none under ground, they moved."""
    problems = []
    if abs(len(z) - expected) > max(2, expected // 1000):
        problems.append(f"{label}: {len(z):,} particles alive at the end, expected {expected:,}")
    if len(z) == 0:
        return problems + [f"{label}: no particles"]
    if z.min() < -GROUND_TOLERANCE:
        problems.append(f"{label}: {int((z < -GROUND_TOLERANCE).sum()):,} particles below the "
                        f"ground (lowest z = {z.min():.4f} m)")
    moved = np.abs(z - EMITTER_Z) > 0.05
    if moved.mean() < 0.5:
        problems.append(f"{label}: only {moved.mean():.0%} of the particles left the emitter "
                        "height")
    return problems


# --- part 1: Blender built-in --------------------------------------------------------------------

def _plane(bpy, scene, name: str, half_size: float, z: float):
    import bmesh

    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bmesh.ops.create_grid(bm, x_segments=1, y_segments=1, size=half_size)  # facing +Z
    bm.to_mesh(me)
    bm.free()
    ob = bpy.data.objects.new(name, me)
    scene.collection.objects.link(ob)
    ob.location = (0.0, 0.0, z)
    return ob


def _empty_file(bpy):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = FPS, 1.0
    return scene


@contextlib.contextmanager
def _quiet_c_stdout():
    """Silence C-level stdout (``ptcache.bake`` prints one line per frame from C)."""
    sys.stdout.flush()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


def run_blender(sc: Scene, method: str) -> Run:
    import bpy

    scene = _empty_file(bpy)
    scene.frame_start, scene.frame_end = 1, sc.frames
    emitter = _plane(bpy, scene, "Emitter", 1.0, EMITTER_Z)
    ground = _plane(bpy, scene, "Ground", 20.0, 0.0)
    emitter.modifiers.new("Particles", type='PARTICLE_SYSTEM')
    psys = emitter.particle_systems[0]
    s = psys.settings
    s.count = sc.count
    s.frame_start, s.frame_end = 1, 1 + sc.emit_frames
    s.lifetime = sc.lifetime
    s.lifetime_random = 0.0
    s.emit_from = 'FACE'
    s.normal_factor = SPEED
    s.physics_type = 'NEWTON'
    ground.modifiers.new("Collision", type='COLLISION')
    ground.collision.damping_factor = 1.0 - RESTITUTION  # normal speed kept = 1 - damping
    ground.collision.friction_factor = FRICTION
    cache = psys.point_cache
    cache.frame_start, cache.frame_end = 1, sc.frames
    note = (f"{s.integrator.lower()} integrator, timestep {s.timestep:.3f} s, "
            f"subframes {s.subframes}, mesh collision")

    def simulate():
        if method == "bake":
            scene.frame_set(1)
            with bpy.context.temp_override(scene=scene, point_cache=cache), _quiet_c_stdout():
                bpy.ops.ptcache.bake(bake=True)
            scene.frame_set(sc.frames)
        else:  # the point cache fills while stepping frame by frame
            for frame in range(1, sc.frames + 1):
                scene.frame_set(frame)

    _, wall, cpu = _timed(simulate)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    particles = emitter.evaluated_get(depsgraph).particle_systems[0].particles
    n = len(particles)
    loc = np.empty(n * 3, np.float32)
    particles.foreach_get("location", loc)
    state = np.empty(n, np.int32)
    particles.foreach_get("alive_state", state)
    alive = state == 3  # enum DEAD=1, UNBORN=2, ALIVE=3, DYING=4 (DNA PARS_*)
    z = loc.reshape(-1, 3)[alive, 2]
    label = "Blender"
    problems = check_points(label, z, sc.count)
    if not cache.info.startswith(f"{sc.frames} frames"):
        problems.append(f"{label}: point cache says {cache.info!r}")
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)  # frees the point cache
    return Run(f"Blender built-in ({method})", wall, cpu, int(alive.sum()), problems, note)


# --- part 1: physanim through the add-on -------------------------------------------------------

def build_physanim_scene(bpy, sc: Scene, folder: str):
    scene = _empty_file(bpy)
    scene.frame_start, scene.frame_end = 1, sc.frames
    emitter = _plane(bpy, scene, "Emitter", 1.0, EMITTER_Z)
    ground = _plane(bpy, scene, "Ground", 20.0, 0.0)
    p = emitter.physanim.emitter
    p.enabled = True
    p.source = 'FACES'
    p.direction = 'NORMAL'
    p.rate, p.rate_random = sc.rate, 0.0
    p.frame_start, p.frame_end = 1, 1 + sc.emit_frames  # active while start <= frame < end
    p.lifetime, p.lifetime_random = sc.lifetime, 0.0
    p.speed, p.speed_random = SPEED, 0.0
    p.spread = 0.0
    col = ground.physanim.collider
    col.enabled = True
    col.shape = 'HALF_SPACE'
    col.restitution, col.friction = RESTITUTION, FRICTION
    settings = scene.physanim
    settings.frame_start, settings.frame_end = 1, sc.frames
    settings.substeps = 1
    settings.integrator = 'SYMPLECTIC_EULER'
    path = os.path.join(folder, "bench_particles.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)  # '//' cache paths need a saved file
    return scene, bpy.data.objects["Emitter"]


def _bake(bpy):
    with contextlib.redirect_stdout(io.StringIO()):  # the bake prints one line per frame
        result = bpy.ops.physanim.bake()
    if 'FINISHED' not in result:
        raise RuntimeError(f"physanim bake returned {result}")


def run_physanim_bake(sc: Scene, folder: str) -> Run:
    import bpy

    scene, emitter = build_physanim_scene(bpy, sc, folder)
    _, wall, cpu = _timed(lambda: _bake(bpy))
    scene.frame_set(sc.frames)
    me = emitter.physanim.emitter.result.data
    n = len(me.vertices)
    pos = np.empty(n * 3, np.float32)
    if n:
        me.attributes["position"].data.foreach_get("vector", pos)
    problems = check_points("physanim bake", pos.reshape(-1, 3)[:, 2], sc.count)
    info = scene.physanim.bake_info
    _cleanup_cache(bpy, folder)
    return Run("physanim bake (add-on, incl. cache)", wall, cpu, n, problems,
               "symplectic Euler, 1 substep, CCD half-space; " + info.split(": ", 1)[-1])


def profile_physanim_bake(sc: Scene, folder: str, top: int) -> str:
    import bpy

    build_physanim_scene(bpy, sc, folder)
    prof = cProfile.Profile()
    gc.collect()
    prof.enable()
    _bake(bpy)
    prof.disable()
    _cleanup_cache(bpy, folder)
    return format_profile(prof, top)


def _cleanup_cache(bpy, folder: str) -> None:
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    shutil.rmtree(os.path.join(folder, "physanim_cache"), ignore_errors=True)


_REAL: dict[str, str] = {}


def _layer(file: str) -> str | None:
    """'core' or 'addon' when ``file`` is a source file of this checkout (the extension runs it
    through a symlinked repo folder), else None."""
    if file not in _REAL:
        _REAL[file] = os.path.realpath(file) if file.endswith(".py") else ""
    real = _REAL[file]
    for layer in ("core", "addon"):
        if real.startswith(str(ROOT / layer) + os.sep):
            return layer
    return None


def _short(key) -> str:
    file, line, func = key
    if file == "~":
        return func  # a builtin, e.g. <method 'reduce' of 'numpy.ufunc' objects>
    if _layer(file):
        return f"{os.path.relpath(_REAL[file], ROOT)}:{line} {func}"
    return f"{'/'.join(Path(file).parts[-2:])}:{line} {func}"


def format_profile(prof: cProfile.Profile, top: int) -> str:
    stats = pstats.Stats(prof)
    total = max(stats.total_tt, 1e-12)
    entries = stats.stats  # key -> (primitive calls, calls, tottime, cumtime, callers)

    out = [f"cProfile of one physanim bake: {total:.2f} s profiled (profiling overhead "
           "included; shares, not absolute times, are what matter)", ""]
    core = [k for k in entries if _layer(k[0]) == "core"]
    addon = [k for k in entries if _layer(k[0]) == "addon"]
    for title, keys, sort in (("core functions by cumulative time", core, 3),
                              ("add-on functions by cumulative time", addon, 3),
                              ("all functions by own time (tottime)", list(entries), 2)):
        rows = sorted(keys, key=lambda k: entries[k][sort], reverse=True)[:top]
        out += [f"**{title}**", "",
                "| function | calls | cumulative (s) | % of bake | own (s) | own % |",
                "|---|---:|---:|---:|---:|---:|"]
        for k in rows:
            _, nc, tt, ct, _ = entries[k]
            out.append(f"| `{_short(k)}` | {nc:,} | {ct:.2f} | {100 * ct / total:.1f} | "
                       f"{tt:.2f} | {100 * tt / total:.1f} |")
        out.append("")
    return "\n".join(out)


# --- part 1: the physanim core alone --------------------------------------------------------------

def _translation(z: float) -> np.ndarray:
    m = np.eye(4)
    m[2, 3] = z
    return m


def run_core(sc: Scene) -> Run:
    P = _core()
    verts = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [-1.0, 1.0, 0.0], [1.0, 1.0, 0.0]])
    tris = np.array([[0, 1, 3], [0, 3, 2]])  # the grid quad's two triangles, facing +Z
    builder = P.ParticleModelBuilder(seed=0)
    builder.add_emitter(P.EmitterSettings(name="Emitter", source="FACES", direction="NORMAL",
                                          triangles=tris, vertex_count=len(verts)))
    model = builder.finalize(1)
    solver = P.ParticleSolver(model, "SYMPLECTIC_EULER", 1)
    dt = 1.0 / FPS
    m_emit, m_ground = _translation(EMITTER_Z), np.eye(4)
    ground = P.ColliderFrame("Ground", "HALF_SPACE", m_ground, m_ground, RESTITUTION, FRICTION)

    def inputs(frame: int):  # what the add-on's extractor hands the solver for [frame, frame+1]
        emitter = P.EmitterFrame(
            rate=sc.rate, speed=SPEED, lifetime=sc.lifetime * dt, mass=0.1, size=0.05,
            spread=0.0, active=1 <= frame < 1 + sc.emit_frames, matrix0=m_emit,
            matrix1=m_emit.copy(), verts0=verts, verts1=verts.copy())
        return P.FrameInputs(frame=frame, t0=frame * dt, frame_dt=dt, emitters=[emitter],
                             colliders=[ground])

    state = model.state(1 * dt)

    def simulate():
        for frame in range(1, sc.frames):
            solver.advance(state, inputs(frame))

    _, wall, cpu = _timed(simulate)
    problems = check_points("physanim core", state.particle_x[:, 2], sc.count)
    return Run("physanim core solver only (no Blender, no cache)", wall, cpu,
               state.particle_count, problems, "same solver settings as the bake")


# --- part 2: steady state per particle-step -------------------------------------------------------

def steady(n: int, integrator: str, frames: int) -> dict:
    P = _core()
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
    ground = P.ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4), RESTITUTION, FRICTION)
    idle = P.EmitterFrame(active=False)

    def inputs(frame):
        return P.FrameInputs(frame=frame, t0=frame * dt, frame_dt=dt, emitters=[idle],
                             colliders=[ground])

    solver.advance(state, inputs(0))  # warm-up (allocations, caches)
    times = []
    collisions = 0
    for frame in range(1, frames + 1):
        report, wall, _ = _timed(lambda f=frame: solver.advance(state, inputs(f)))
        times.append(wall)
        collisions += report.collisions
    times = np.array(times)
    return {"n": n, "integrator": integrator, "frame_ms": 1e3 * times.mean(),
            "ns_mean": 1e9 * times.mean() / n, "ns_min": 1e9 * times.min() / n,
            "collisions": collisions, "alive": state.particle_count}


# --- output ------------------------------------------------------------------------------------

def compare_table(runs: list[Run], sc: Scene) -> str:
    base = next((r for r in runs if r.name.startswith("Blender")), None)
    lines = [f"### {sc.count:,} particles, {sc.frames} frames at {FPS} fps (emitted over frames "
             f"1-{1 + sc.emit_frames}), bouncing on a ground", "",
             "| simulator | time (s) | CPU time (s) | particles at end | ratio vs Blender |",
             "|---|---:|---:|---:|---:|"]
    for r in runs:
        ratio = f"{r.wall / base.wall:.2f}" if base else "n/a"
        lines.append(f"| {r.name} | {r.wall:.2f} | {r.cpu:.2f} | {r.particles:,} | {ratio} |")
    lines.append("")
    for r in runs:
        if r.note:
            lines.append(f"- {r.name}: {r.note}")
    bake = next((r for r in runs if r.name.startswith("physanim bake")), None)
    if base and bake:
        met = "met" if bake.wall <= 0.5 * base.wall else "NOT met"
        lines.append(f"- target physanim bake <= 0.5 x Blender: {met} "
                     f"({bake.wall / base.wall:.2f} x)")
    return "\n".join(lines)


def steady_table(rows: list[dict], frames: int) -> str:
    lines = [f"### Core solver, steady state ({frames} frames of 1 substep after a warm-up; "
             "particles in the air above a half-space ground)", "",
             "| particles | integrator | ms / frame | ns / particle-step (mean) | "
             "ns / particle-step (best) |",
             "|---:|---|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['n']:,} | {r['integrator']} | {r['frame_ms']:.1f} | "
                     f"{r['ns_mean']:.0f} | {r['ns_min']:.0f} |")
    return "\n".join(lines)


def _load() -> str:
    try:
        return " ".join(f"{v:.2f}" for v in os.getloadavg())
    except OSError:
        return "n/a"


def _blas_threads() -> str:
    knobs = [f"{k}={os.environ[k]}" for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")
             if k in os.environ]
    return f", {', '.join(knobs)}" if knobs else ""


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--quick", action="store_true",
                    help="smoke run: 20k particles, 60 frames, steady sizes 10k and 100k")
    ap.add_argument("--count", type=int, help="particles emitted (default 100000)")
    ap.add_argument("--frames", type=int, help="frames simulated (default 250)")
    ap.add_argument("--emit-frames", type=int,
                    help="frames over which all particles are born (default min(100, 2/5 frames))")
    ap.add_argument("--sizes", help="steady-state particle counts (default 10000,100000,1000000)")
    ap.add_argument("--steady-frames", type=int, help="timed frames per steady run (default 5)")
    ap.add_argument("--integrators", default="SYMPLECTIC_EULER,RK4")
    ap.add_argument("--blender-method", choices=("frames", "bake"), default="frames",
                    help="frame_set(1..F) from an empty cache (default) or ptcache.bake")
    ap.add_argument("--parts", default="compare,steady",
                    help="comma list of: compare, steady (add profile with --profile)")
    ap.add_argument("--no-blender", action="store_true",
                    help="compare: skip Blender's built-in run")
    ap.add_argument("--profile", action="store_true",
                    help="also profile one extra physanim bake with cProfile")
    ap.add_argument("--top", type=int, default=15, help="rows per profile table")
    args = ap.parse_args(argv)
    count = args.count or (20_000 if args.quick else 100_000)
    frames = args.frames or (60 if args.quick else 250)
    if frames < 2 or count < 1:
        ap.error("need --frames >= 2 and --count >= 1")
    emit = args.emit_frames or max(1, min(100, (2 * frames) // 5))
    sc = Scene(count, frames, min(emit, frames - 1))
    sizes = [int(s) for s in (args.sizes or ("10000,100000" if args.quick else
                                             "10000,100000,1000000")).split(",") if s]
    steady_frames = args.steady_frames or (3 if args.quick else 5)
    parts = {p.strip() for p in args.parts.split(",") if p.strip()}
    if args.profile:
        parts.add("profile")

    import bpy

    print(f"# physanim particle benchmark — Blender {bpy.app.version_string}, numpy "
          f"{np.__version__}, Python {platform.python_version()}, {os.cpu_count()} CPUs, "
          f"load average {_load()}{_blas_threads()}\n", flush=True)
    problems: list[str] = []
    folder = tempfile.mkdtemp(prefix="physanim_bench_")
    blender_env.enable_extension()
    try:
        if "compare" in parts:
            runs = []
            if not args.no_blender:
                runs.append(run_blender(sc, args.blender_method))
                print(f"(Blender: {runs[-1].wall:.2f} s)", flush=True)
            runs.append(run_physanim_bake(sc, folder))
            print(f"(physanim bake: {runs[-1].wall:.2f} s)", flush=True)
            runs.append(run_core(sc))
            print(f"(physanim core: {runs[-1].wall:.2f} s)\n", flush=True)
            print(compare_table(runs, sc) + "\n", flush=True)
            problems += [p for r in runs for p in r.problems]
        if "steady" in parts:
            rows = []
            for n in sizes:
                for integrator in args.integrators.split(","):
                    row = steady(n, integrator.strip(), steady_frames)
                    rows.append(row)
                    if row["alive"] != n or row["collisions"]:
                        problems.append(f"steady {n:,} {row['integrator']}: {row['alive']:,} "
                                        f"alive, {row['collisions']} collisions (expected {n:,}, "
                                        "0: the setup is not steady)")
                    gc.collect()
            print(steady_table(rows, steady_frames) + "\n", flush=True)
        if "profile" in parts:
            print(profile_physanim_bake(sc, folder, args.top), flush=True)
    finally:
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        blender_env.disable_extension()
        shutil.rmtree(folder, ignore_errors=True)
    print(f"load average at the end: {_load()} (other work on the machine skews timings)")
    for p in problems:
        print("SANITY CHECK FAILED:", p)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
