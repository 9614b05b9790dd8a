"""Part 1 of the particle benchmark (``bench/particles.py``), "compare": the scene, and the
three runs of it — Blender's built-in particle system, the physanim bake through the add-on, the
physanim core alone — each checked afterwards. Also the cProfile of one more physanim bake.
"""
from __future__ import annotations

import contextlib
import cProfile
import gc
import importlib
import io
import os
import shutil
from dataclasses import dataclass

import numpy as np

from bench import blender_side, common, profiling

FPS = 25  # Blender's particle timestep defaults to 0.04 s/frame: 25 fps makes both agree
EMITTER_Z = 2.0  # [m] height of the emitting plane
SPEED = 2.0  # [m/s] initial speed along the plane's normal
RESTITUTION, FRICTION = 0.5, 0.3
GROUND_HALF = 20.0  # [m] half the ground grid's side
GROUND_TOLERANCE = 1e-3  # [m] a particle lower than this below z = 0 went through the ground


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
    cpu: float  # [s] CPU time: all threads (Blender's may be several) and child processes
    particles: int
    problems: list[str]
    note: str = ""


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


def _emitter_and_ground(sc: Scene):
    """A fresh file holding the 2 x 2 m emitting plane and the 40 x 40 m ground mesh."""
    scene = blender_side.empty_scene(FPS, sc.frames)
    emitter = blender_side.grid_object(scene, "Emitter", 1, 1.0, EMITTER_Z)
    ground = blender_side.grid_object(scene, "Ground", 1, GROUND_HALF, 0.0)
    return scene, emitter, ground


# --- part 1: Blender built-in --------------------------------------------------------------------

def _add_blender_particles(sc: Scene, emitter, ground):
    """The ParticleSystem modifier on the emitter and the Collision modifier on the ground."""
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
    psys.point_cache.frame_start, psys.point_cache.frame_end = 1, sc.frames
    return psys


def _alive_heights(emitter) -> np.ndarray:
    """z [m] of the emitter's evaluated particles that are alive."""
    import bpy

    depsgraph = bpy.context.evaluated_depsgraph_get()
    particles = emitter.evaluated_get(depsgraph).particle_systems[0].particles
    n = len(particles)
    loc = np.empty(n * 3, np.float32)
    particles.foreach_get("location", loc)
    state = np.empty(n, np.int32)
    particles.foreach_get("alive_state", state)
    alive = state == 3  # enum DEAD=1, UNBORN=2, ALIVE=3, DYING=4 (DNA PARS_*)
    return loc.reshape(-1, 3)[alive, 2]


def run_blender(sc: Scene, method: str) -> Run:
    import bpy

    scene, emitter, ground = _emitter_and_ground(sc)
    psys = _add_blender_particles(sc, emitter, ground)
    s, cache = psys.settings, psys.point_cache
    note = (f"{s.integrator.lower()} integrator, timestep {s.timestep:.3f} s, "
            f"subframes {s.subframes}, mesh collision")

    def simulate():
        if method == "bake":
            scene.frame_set(1)
            with (bpy.context.temp_override(scene=scene, point_cache=cache),
                  blender_side.quiet_c_stdout()):
                bpy.ops.ptcache.bake(bake=True)
            scene.frame_set(sc.frames)
        else:  # the point cache fills while stepping frame by frame
            for frame in range(1, sc.frames + 1):
                scene.frame_set(frame)

    _, wall, cpu = common.timed(simulate)
    z = _alive_heights(emitter)
    label = "Blender"
    problems = check_points(label, z, sc.count)
    if not cache.info.startswith(f"{sc.frames} frames"):
        problems.append(f"{label}: point cache says {cache.info!r}")
    blender_side.reset()  # frees the point cache
    return Run(f"Blender built-in ({method})", wall, cpu, len(z), problems, note)


# --- part 1: physanim through the add-on -------------------------------------------------------

# The tuned row's settings (the headline row leaves the scene's defaults: 2 substeps, symplectic
# Euler, an Automatic collider, which fits the ground grid as a rectangle)
TUNED = {"substeps": 1, "shape": 'HALF_SPACE'}
TARGET_DEFAULTS, TARGET_TUNED = 0.35, 0.25  # physanim / Blender time (issue 12)


def build_physanim_scene(sc: Scene, folder: str, tuned: bool = False):
    """The scene with the emitter and the ground as physanim objects; only the emitter's keys
    that make the scene are set (and the TUNED settings when ``tuned``)."""
    import bpy

    scene, emitter, ground = _emitter_and_ground(sc)
    p = emitter.physanim.emitter
    p.enabled = True
    p.source = 'FACES'
    p.direction = 'NORMAL'
    p.rate, p.rate_random = sc.rate, 0.0
    # inclusive window: the births of frame f happen during f - 1 -> f, so frames 2..1 + emit
    # emit during [1, 1 + emit], as Blender's system (frames 1..1 + emit) and the core run do
    p.frame_start, p.frame_end = 2, 1 + sc.emit_frames
    p.lifetime, p.lifetime_random = sc.lifetime, 0.0
    p.speed, p.speed_random = SPEED, 0.0
    p.spread = 0.0
    col = ground.physanim.collider
    col.enabled = True
    col.restitution, col.friction = RESTITUTION, FRICTION
    settings = scene.physanim
    settings.frame_start, settings.frame_end = 1, sc.frames
    if tuned:
        col.shape = TUNED["shape"]
        settings.substeps = TUNED["substeps"]
    path = os.path.join(folder, "bench_particles.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)  # '//' cache paths need a saved file
    return scene, bpy.data.objects["Emitter"]


def _bake() -> None:
    import bpy

    with contextlib.redirect_stdout(io.StringIO()):  # the bake prints one line per frame
        result = bpy.ops.physanim.bake()
    if 'FINISHED' not in result:
        raise RuntimeError(f"physanim bake returned {result}")


def run_physanim_bake(sc: Scene, folder: str, tuned: bool = False) -> Run:
    scene, emitter = build_physanim_scene(sc, folder, tuned)
    _, wall, cpu = common.timed(_bake)
    scene.frame_set(sc.frames)
    from sample_scenes._common import result_points  # the result as Blender shows it

    pos = result_points(emitter.physanim.emitter.result)["position"]
    n = len(pos)
    problems = check_points("physanim bake", pos[:, 2], sc.count)
    info = scene.physanim.bake_info
    what = (f"tuned: {TUNED['substeps']} substep, {TUNED['shape'].lower().replace('_', '-')} "
            "ground" if tuned else f"defaults: {scene.physanim.substeps} substeps, "
            f"{scene.physanim.integrator.lower().replace('_', ' ')}, Automatic ground")
    _cleanup_cache(folder)
    return Run(f"physanim bake (add-on, {what}, incl. cache)", wall, cpu, n, problems,
               info.split(": ", 1)[-1])


def profile_physanim_bake(sc: Scene, folder: str, top: int) -> str:
    build_physanim_scene(sc, folder)
    prof = cProfile.Profile()
    gc.collect()
    prof.enable()
    _bake()
    prof.disable()
    _cleanup_cache(folder)
    return profiling.format_profile(prof, top)


def _cleanup_cache(folder: str) -> None:
    blender_side.reset()
    shutil.rmtree(os.path.join(folder, "physanim_cache"), ignore_errors=True)


# --- part 1: the physanim core alone --------------------------------------------------------------

def _translation(z: float) -> np.ndarray:
    m = np.eye(4)
    m[2, 3] = z
    return m


def default_substeps() -> int:
    """The scene's default substeps per frame (what the headline rows run)."""
    import bpy

    return int(bpy.context.scene.physanim.bl_rna.properties["substeps"].default)


def run_core(sc: Scene, substeps: int) -> Run:
    """The scene straight through the core at ``substeps``, the ground as the bake's Automatic
    collider sees the 40 x 40 m grid (a rectangle)."""
    P, contact = common.core_module("particles"), common.core_module("contact")
    verts = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [-1.0, 1.0, 0.0], [1.0, 1.0, 0.0]])
    tris = np.array([[0, 1, 3], [0, 3, 2]])  # the grid quad's two triangles, facing +Z
    builder = P.ParticleModelBuilder(seed=0)
    builder.add_emitter(P.EmitterSettings(name="Emitter", source="FACES", direction="NORMAL",
                                          triangles=tris, vertex_count=len(verts)))
    model = builder.finalize(1)
    solver = P.ParticleSolver(model, "SYMPLECTIC_EULER", substeps)
    dt = 1.0 / FPS
    m_emit, m_ground = _translation(EMITTER_Z), np.diag([GROUND_HALF, GROUND_HALF, 1.0, 1.0])
    ground = contact.ColliderFrame("Ground", "PLANE", m_ground, m_ground, RESTITUTION,
                                   FRICTION)

    def inputs(frame: int):  # what the add-on's extractor hands the solver for [frame, frame+1]
        emitter = P.EmitterFrame(
            rate=sc.rate, speed=SPEED, lifetime=sc.lifetime * dt, mass=0.1, size=0.05,
            spread=0.0, active=1 <= frame < 1 + sc.emit_frames, matrix0=m_emit,
            matrix1=m_emit.copy(), verts0=verts, verts1=verts.copy())
        return P.FrameInputs(frame=frame, t0=frame * dt, frame_dt=dt, emitters=[emitter],
                             colliders=[ground])

    state = model.state(1 * dt)

    def simulate():
        with allocator.reuse():  # as the bake does
            for frame in range(1, sc.frames):
                solver.advance(state, inputs(frame))

    allocator = importlib.import_module("physanim.addon.allocator")  # stdlib only
    _, wall, cpu = common.timed(simulate)
    problems = check_points("physanim core", state.particle_x[:, 2], sc.count)
    return Run(f"physanim core solver only ({substeps} substeps, no Blender, no cache)", wall,
               cpu, state.particle_count, problems, "the headline bake's solver settings and memory reuse")


# --- the table ------------------------------------------------------------------------------------

def compare_table(runs: list[Run], sc: Scene) -> str:
    base = next((r for r in runs if r.name.startswith("Blender")), None)
    rows = [(r.name, f"{r.wall:.2f}", f"{r.cpu:.2f}", f"{r.particles:,}",
             f"{r.wall / base.wall:.2f}" if base else "n/a") for r in runs]
    lines = [f"### {sc.count:,} particles, {sc.frames} frames at {FPS} fps (emitted over frames "
             f"1-{1 + sc.emit_frames}), bouncing on a ground", "",
             *common.markdown_table(("simulator", "time (s)", "CPU time (s)", "particles at end",
                                     "ratio vs Blender"), "lrrrr", rows), ""]
    for r in runs:
        if r.note:
            lines.append(f"- {r.name}: {r.note}")
    for key, target in (("defaults", TARGET_DEFAULTS), ("tuned", TARGET_TUNED)):
        bake = next((r for r in runs if r.name.startswith(f"physanim bake (add-on, {key}")),
                    None)
        if base and bake:
            met = "met" if bake.wall <= target * base.wall else "NOT met"
            lines.append(f"- target physanim bake ({key}) <= {target} x Blender: {met} "
                         f"({bake.wall / base.wall:.2f} x)")
    return "\n".join(lines)
