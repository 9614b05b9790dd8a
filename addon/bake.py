"""A particle bake as a resumable job: prepare -> step (one frame each) -> finish | abort.

The operator drives it synchronously (background, scripts, CLI) or from a modal timer (UI, with
progress and ESC). Frames stream into a fresh cache folder per emitter; :meth:`BakeJob.finish`
swaps them in and writes native results, :meth:`BakeJob.abort` deletes the partial folders so the
previous bake stays exactly as it was.
"""
from __future__ import annotations

import contextlib
import hashlib
import os
import re
import shutil
import time

import bpy
import numpy as np

from ..core.cache import CacheWriter
from ..core.errors import PhysanimError, SimulationError
from ..core.integrators import make_integrator
from ..core.particles import ParticleSolver, emitter_arrays
from ..core.contact import ColliderPaths
from . import convert, extract, limits, springs

STREAM = "points"
BYTES_PER_PARTICLE_FRAME = 4 * (1 + 3 + 3 + 1 + 1 + 1 + 4 + 3 + 3)  # cache arrays of output.py
BYTES_PER_PARTICLE_STATE = 8 * 16  # float64 state + integrator stages, per particle
MEMORY_BUDGET = 16 * 2**30  # the bake refuses to start when its estimate exceeds this
FLOAT32_MAX = float(np.finfo(np.float32).max)  # the cache stores float32


def safe_name(name: str) -> str:
    """A file-system safe, readable and unique folder name for an object or scene name: the
    readable part may collide ("Fire 1", "Fire_1"), so a hash of the exact name follows it."""
    readable = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "object"
    return f"{readable[:48]}-{hashlib.sha1(name.encode('utf-8')).hexdigest()[:8]}"


def cache_root(scene) -> str:
    """Absolute cache folder of a scene; errors when a '//' path has no saved .blend to anchor it."""
    raw = scene.physanim.cache_dir.strip()
    if not raw:
        raise PhysanimError("the cache folder is empty — set Scene > PhysAnim > Cache",
                            obj=scene.name, kind="scene")
    if raw.startswith("//") and not bpy.data.filepath:
        raise PhysanimError(f'the cache folder "{raw}" is relative to the .blend file, which is not '
                            "saved yet — save the file first or choose an absolute cache folder",
                            obj=scene.name, kind="scene")
    return os.path.normpath(bpy.path.abspath(raw))


def emitter_cache_dir(scene, ob) -> str:
    return os.path.join(cache_root(scene), safe_name(scene.name), safe_name(ob.name))


def spring_cache_dir(scene, ob) -> str:
    """Spring meshes bake into their own sub-folder: an object may also be an emitter."""
    return os.path.join(cache_root(scene), safe_name(scene.name), "spring_meshes",
                        safe_name(ob.name))


def relative_path(path: str) -> str:
    """'//'-relative path with forward slashes when the .blend is saved (else absolute)."""
    if bpy.data.filepath:
        try:
            return bpy.path.relpath(path).replace("\\", "/")
        except ValueError:  # other drive on Windows
            pass
    return path.replace("\\", "/")


def estimate(scene, roles: extract.Roles) -> tuple[float, float]:
    """Peak alive particles and cache bytes of a bake, from rates and lifetimes (upper bounds)."""
    frames = max(0, scene.physanim.frame_end - scene.physanim.frame_start) + 1
    peak_by_name: dict[str, float] = {}
    total_bytes = 0.0
    for ob in roles.emitters:  # parents first is not guaranteed: resolve sub-emitters after
        p = ob.physanim.emitter
        if p.source == 'DEATHS':
            continue
        active = max(0, min(p.frame_end, scene.physanim.frame_end)
                     - max(p.frame_start, scene.physanim.frame_start) + 1)  # inclusive window
        life = p.lifetime + p.lifetime_random
        peak_by_name[ob.name] = (p.rate + p.rate_random) * min(life, active) if active else 0.0
        total_bytes += (p.rate + p.rate_random) * active * min(life, frames) * BYTES_PER_PARTICLE_FRAME
    births_per_frame = {ob.name: ob.physanim.emitter.rate + ob.physanim.emitter.rate_random
                        for ob in roles.emitters if ob.physanim.emitter.source != 'DEATHS'}
    for _ in range(len(roles.emitters)):  # resolve chains of sub-emitters, parents first
        for ob in roles.emitters:
            p = ob.physanim.emitter
            if (p.source == 'DEATHS' and p.parent and p.parent.name in births_per_frame
                    and ob.name not in births_per_frame):
                # at most every parent birth dies within the bake and bursts rate + r children
                births_per_frame[ob.name] = births_per_frame[p.parent.name] * (p.rate + p.rate_random)
                life = p.lifetime + p.lifetime_random
                peak_by_name[ob.name] = births_per_frame[ob.name] * min(life, frames)
                total_bytes += (births_per_frame[ob.name] * frames * min(life, frames)
                                * BYTES_PER_PARTICLE_FRAME)
    return sum(peak_by_name.values()), total_bytes


class BakeJob:
    """Bake every (or the chosen) particle emitter of a scene, one frame per :meth:`step`.

    Args:
        context: Blender context. only: emitter names to bake (None = all of them).
    """

    def __init__(self, context, only: set[str] | None = None):
        self.scene = context.scene
        self.view_layer = context.view_layer
        self.settings = self.scene.physanim
        self.original_frame = self.scene.frame_current
        self.roles = extract.gather(self.scene, only)
        if not self.roles.emitters and not self.roles.spring_meshes:
            raise PhysanimError("nothing to bake: no object has a PhysAnim emitter or spring "
                                "mesh enabled", obj=self.scene.name, kind="scene")
        self.frame_start = self.settings.frame_start
        self.frame_end = self.settings.frame_end
        if self.frame_end < self.frame_start:
            raise PhysanimError(f"frame end {self.frame_end} is before frame start {self.frame_start}",
                                obj=self.scene.name, kind="scene")
        limits.check_scene(self.scene, self.frame_start, self.frame_end)
        self._check_budget()
        self.writers: dict[str, CacheWriter] = {}
        self.frame = self.frame_start
        self.started = time.perf_counter()
        self.stats = {"births": 0, "collisions": 0, "peak": 0}
        self.births = {ob.name: 0 for ob in self.roles.emitters}
        self.meshes: list[springs.SpringMeshBake] = []
        self.colliders = ColliderPaths()  # every system's colliders, kept for the whole run
        self.mesh_writers: dict[str, CacheWriter] = {}
        # systems that failed: (what, message); the others still bake (see _system)
        self.failures: list[tuple[str, str]] = []
        from . import results

        results.suspend_refresh(self.scene)  # our own frame changes must not reload old bakes
        # the bake reads each spring mesh without its previous cache playing on top
        self.suspended = {ob.name: springs.suspend_modifier(ob) for ob in self.roles.spring_meshes}
        try:
            for ob in self.roles.emitters:
                self.writers[ob.name] = CacheWriter(emitter_cache_dir(self.scene, ob))
            for ob in self.roles.spring_meshes:
                self.mesh_writers[ob.name] = CacheWriter(spring_cache_dir(self.scene, ob))
            all_roles = extract.gather(self.scene)
            self.hashes = {ob.name: extract.emitter_hash(self.scene, ob, all_roles)
                           for ob in self.roles.emitters}
            self.mesh_hashes = {ob.name: extract.inputs_hash(self.scene, ob, "spring_mesh",
                                                             all_roles)
                                for ob in self.roles.spring_meshes}
            self.extractor = extract.Extractor(self.scene, self.roles)
            self.scene.frame_set(self.frame_start)
            depsgraph = context.evaluated_depsgraph_get()
            for ob in self.roles.spring_meshes:
                with self._system(ob.name):
                    bake = springs.SpringMeshBake(self.scene, ob, self.mesh_writers[ob.name],
                                                  self.frame_start, self.colliders)
                    self.meshes.append(bake)
                    bake.prepare(depsgraph, self.frame_start)
            self.objects_limit = {ob.name for ob in self.roles.emitters
                                  if ob.physanim.emitter.output == 'OBJECTS'}
            with self._system(None):
                self.model = self.extractor.build_model(depsgraph, self.frame_start)
                self.solver = ParticleSolver(self.model, self.settings.integrator,
                                             self.settings.substeps, self.settings.tolerance,
                                             limits.bounds(self.scene), self.colliders)
            self.sample = self.extractor.sample(depsgraph, self.frame_start, emitters=False)
            self.sample.emitters = self._emitter_read(
                lambda: self.extractor.sample_emitters(depsgraph, self.frame_start))
            if self.particles_live:
                with self._system(None):
                    self._first_births()
                    self._write_frame(self.frame_start)
        except BaseException:
            self.abort()
            raise

    @contextlib.contextmanager
    def _system(self, mesh: str | None):
        """Run one system's work (the spring mesh named ``mesh``, or the particles when None):
        when it fails, that system is dropped — its partial cache deleted, its previous bake
        kept — and the others go on; the bake reports every failure at its end. Only when no
        system is left does the error stop the whole bake."""
        try:
            yield
        except (PhysanimError, ValueError) as exc:
            if mesh is None:
                what = ", ".join(f'"{ob.name}"' for ob in self.roles.emitters)
                what = f"particles (emitter{'s' if len(self.roles.emitters) > 1 else ''} {what})"
                for writer in self.writers.values():
                    writer.abort()
                self.writers.clear()
            else:
                what = f'spring mesh "{mesh}"'
                for bake in [b for b in self.meshes if b.ob.name == mesh]:
                    bake.close()
                    self.meshes.remove(bake)
                self.mesh_writers.pop(mesh).abort()
                springs.restore_modifier(bpy.data.objects[mesh], self.suspended.pop(mesh, None))
            self.failures.append((what, str(exc)))
            if not self.writers and not self.mesh_writers:
                raise

    @property
    def particles_live(self) -> bool:
        """Whether the particle system is still baking (it has emitters and has not failed)."""
        return bool(self.writers)

    @property
    def alive(self) -> int:
        """Particles alive now (0 once the particle system failed)."""
        return self.state.particle_count if self.particles_live else 0

    @property
    def total_frames(self) -> int:
        return self.frame_end - self.frame_start

    @property
    def progress(self) -> float:
        return (self.frame - self.frame_start) / max(1, self.total_frames)

    def _check_budget(self) -> None:
        peak, cache_bytes = estimate(self.scene, self.roles)
        stages = make_integrator(self.settings.integrator, self.settings.tolerance).stages
        memory = peak * BYTES_PER_PARTICLE_STATE * (1 + stages)
        if memory > MEMORY_BUDGET:
            raise PhysanimError(
                f"an estimated {peak:,.0f} particles alive at once need about "
                f"{memory / 2**30:.1f} GiB of memory (limit {MEMORY_BUDGET / 2**30:.0f} GiB) — "
                "lower rates or lifetimes", obj=self.scene.name, kind="scene")
        root = cache_root(self.scene)
        probe = root
        while not os.path.exists(probe) and os.path.dirname(probe) != probe:
            probe = os.path.dirname(probe)
        free = shutil.disk_usage(probe).free
        if cache_bytes > free:
            raise PhysanimError(
                f"the cache needs an estimated {cache_bytes / 2**30:.2f} GiB but only "
                f"{free / 2**30:.2f} GiB are free at \"{root}\" — free space or lower rates",
                obj=self.scene.name, kind="scene")

    def _check_cache_range(self, frame: int) -> None:
        """Positions and velocities must fit the float32 cache: a value beyond it would be
        written as inf (silently) although the float64 simulation is still finite."""
        state = self.state
        for what, values in (("position", state.particle_x), ("velocity", state.particle_v),
                             ("size", state.particle_size[:, None]),
                             ("age", state.particle_age[:, None])):
            bad = ~np.isfinite(values).all(axis=1)
            if bad.any():
                i = int(np.argmax(bad))
                raise SimulationError(
                    f"particle {int(state.particle_id[i])} {what} became "
                    f"{np.array2string(values[i], precision=4)} — nothing non-finite is ever "
                    "written to a bake", obj=self.model.emitters[int(state.particle_emitter[i])].name,
                    frame=frame, kind="emitter")
        for what, values, unit in (("position", state.particle_x, "m"),
                                   ("velocity", state.particle_v, "m/s")):
            big = (np.abs(values) > FLOAT32_MAX).any(axis=1)
            if big.any():
                i = int(np.argmax(big))
                raise SimulationError(
                    f"particle {int(state.particle_id[i])} {what} reached "
                    f"{np.array2string(values[i], precision=4)} {unit}, beyond the cache's float32 "
                    f"range (±{FLOAT32_MAX:.3g}) — check the emitter's motion and the forces",
                    obj=self.model.emitters[int(state.particle_emitter[i])].name, frame=frame,
                    kind="emitter")

    def _write_frame(self, frame: int) -> None:
        self._check_cache_range(frame)
        to_frames = convert.fps(self.scene)
        for i, ob in enumerate(self.roles.emitters):
            arrays = emitter_arrays(self.model, self.state, i, frame=frame)
            arrays["age"] = (arrays["age"] * to_frames).astype(np.float32)
            arrays["life"] = (arrays["life"] * to_frames).astype(np.float32)
            self.writers[ob.name].write_frame(STREAM, frame, arrays)
        self.stats["peak"] = max(self.stats["peak"], self.state.particle_count)

    def _interval(self, frame: int, start):
        """Core inputs for the interval ``frame`` -> ``frame + 1`` from the sample ``start`` at
        ``frame``; leaves the scene at ``frame + 1``. Returns (inputs, sample at frame + 1)."""
        between = []
        substeps = self.settings.substeps
        depsgraph = self.view_layer.depsgraph
        for k in range(1, substeps):  # sub-frame motion keys: one per sub-step boundary
            self.scene.frame_set(frame, subframe=k / substeps)
            between.append(self.extractor.sample_motion(emitters=False))
            between[-1][0].extend(self._emitter_read(self.extractor.emitter_motion))
        self.scene.frame_set(frame + 1)
        end = self.extractor.sample(depsgraph, frame + 1, emitters=False)
        end.emitters = self._emitter_read(lambda: self.extractor.sample_emitters(depsgraph,
                                                                                 frame + 1))
        return self.extractor.inputs(start, end, between), end

    def _emitter_read(self, read) -> list:
        """``read()`` of emitter values for the particle system: a failure there is that
        system's (see :meth:`_system`) and leaves the spring meshes baking; [] once the
        particle system has failed."""
        if self.particles_live:
            with self._system(None):
                return read()
        return []

    def _first_births(self) -> None:
        """Births of frame f happen during the interval f - 1 -> f, so they show at frame f
        (emission windows are inclusive: start = end is a one-frame burst). For an emitter
        whose window holds the bake's first frame, that interval lies before the bake: it is
        simulated for the particles alone, which start the bake with ages up to one frame."""
        s = self.frame_start
        if not any(values["active"] for *_, values in self.sample.emitters):
            self.state = self.model.state(convert.frame_time(self.scene, s))
            return
        self.state = self.model.state(convert.frame_time(self.scene, s - 1))
        self.scene.frame_set(s - 1)
        before = self.extractor.sample(self.view_layer.depsgraph, s - 1)
        inputs, self.sample = self._interval(s - 1, before)
        self._record(self.solver.advance(self.state, inputs), s)

    def step(self, context) -> bool:
        """Simulate and write the next frame. Returns True when the bake has reached its end."""
        if self.frame >= self.frame_end:
            return True
        nxt = self.frame + 1
        inputs, sample = self._interval(self.frame, self.sample)
        if self.particles_live:
            with self._system(None):
                self._record(self.solver.advance(self.state, inputs), nxt)
                self._write_frame(nxt)
        for mesh in list(self.meshes):
            with self._system(mesh.ob.name):
                mesh.advance(mesh.read(self.view_layer.depsgraph, nxt), inputs.colliders,
                             inputs.forces, inputs.t0, inputs.frame_dt, inputs.gravity)
        self.sample = sample
        self.frame = nxt
        return self.frame >= self.frame_end

    def _record(self, report, frame: int) -> None:
        self.stats["births"] += report.births
        self.stats["collisions"] += report.collisions
        self._count_births(report, frame)

    def _count_births(self, report, frame: int) -> None:
        """Fail early (before anything is replaced) when the Objects output would get too many
        particles: each particle becomes an object."""
        from .results import MAX_KEYED_OBJECTS

        for i, ob in enumerate(self.roles.emitters):
            self.births[ob.name] += report.per_emitter_births[i]
            if ob.name in self.objects_limit and self.births[ob.name] > MAX_KEYED_OBJECTS:
                raise PhysanimError(
                    f"{self.births[ob.name]:,} particles are too many for the Objects output "
                    f"(limit {MAX_KEYED_OBJECTS:,}) — use the Points output or a lower rate",
                    obj=ob.name, frame=frame, kind="emitter")

    def finish(self, context) -> str:
        """Swap the new caches in and point every emitter's result at them. Returns a summary."""
        from . import results

        meta = {"frame_start": self.frame_start, "frame_end": self.frame_end,
                "fps": convert.fps(self.scene), "kind": "particles"}
        for mesh in self.meshes:
            mesh.close()
        self.colliders.release()
        for writer in [*self.writers.values(), *self.mesh_writers.values()]:
            writer.flush()  # every frame on disk before any bake is swapped in
        emitters = [ob for ob in self.roles.emitters if ob.name in self.writers]
        meshes = [ob for ob in self.roles.spring_meshes if ob.name in self.mesh_writers]
        paths = {ob.name: self.writers[ob.name].commit(dict(meta, emitter=ob.name,
                                                            hash=self.hashes[ob.name]))
                 for ob in emitters}
        mesh_paths = {ob.name: self.mesh_writers[ob.name].commit(
            dict(meta, kind="spring_mesh", object=ob.name, hash=self.mesh_hashes[ob.name]))
            for ob in meshes}
        self.writers.clear()
        self.mesh_writers.clear()
        results.resume_refresh(self.scene)
        for ob in emitters:
            results.attach(context, self.scene, ob,
                           relative_path(os.path.join(paths[ob.name], STREAM)),
                           self.frame_start, self.frame_end, self.hashes[ob.name])
        for ob in meshes:
            springs.attach(ob, relative_path(os.path.join(mesh_paths[ob.name], springs.CACHE_FILE)),
                           self.frame_start, self.mesh_hashes[ob.name], self.suspended.get(ob.name))
        self.suspended.clear()
        self.scene.frame_set(self.original_frame)
        self.settings.bake_hash = extract.scene_hash(
            [*(self.hashes[ob.name] for ob in emitters),
             *(self.mesh_hashes[ob.name] for ob in meshes)])
        took = time.perf_counter() - self.started
        what = f", {len(meshes)} spring mesh(es)" if meshes else ""
        info = (f"baked {len(emitters)} emitter(s){what}, frames {self.frame_start}-"
                f"{self.frame_end}: {self.stats['births']:,} births, peak {self.stats['peak']:,} "
                f"alive, {took:.2f} s")
        self.settings.bake_info = info
        return info

    def failure_report(self, info: str) -> str | None:
        """One message naming every system that failed (each keeps its previous bake) and what
        did bake; None when nothing failed."""
        if not self.failures:
            return None
        failed = "; ".join(message for _, message in self.failures)
        names = ", ".join(what for what, _ in self.failures)
        return (f"{failed} — not baked (previous bake kept): {names}; the rest baked "
                f"({info.removeprefix('baked ')})")

    def abort(self) -> None:
        """Delete partial caches and restore the frame; the previous bake is untouched."""
        from . import results

        for mesh in self.meshes:
            mesh.close()
        self.colliders.release()
        for writer in [*self.writers.values(), *getattr(self, "mesh_writers", {}).values()]:
            writer.abort()
        self.writers.clear()
        self.mesh_writers.clear()
        for ob in self.roles.spring_meshes:
            springs.restore_modifier(ob, self.suspended.get(ob.name))
        self.suspended.clear()
        results.resume_refresh(self.scene)
        if self.scene.frame_current != self.original_frame:
            self.scene.frame_set(self.original_frame)


def run(context, only: set[str] | None = None, on_frame=None) -> tuple[str, str | None]:
    """Bake synchronously. ``on_frame(job)`` is called after each frame (progress, logging).

    Returns the summary line and the failure report of systems that failed while others baked
    (None when none failed); raises PhysanimError/OSError/ValueError after aborting, leaving
    the previous bake intact, when nothing could bake.
    """
    job = BakeJob(context, only)
    try:
        if on_frame is not None:
            on_frame(job)
        while not job.step(context):
            if on_frame is not None:
                on_frame(job)
        if on_frame is not None:
            on_frame(job)
        info = job.finish(context)
        return info, job.failure_report(info)
    except BaseException:
        job.abort()
        raise
