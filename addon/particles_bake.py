"""The particle system of a bake: its emitters' caches, the core model, solver and state, the
pre-roll of the first frame's births, and the frames it writes (npz per emitter and frame)."""
from __future__ import annotations

import numpy as np

from ..core.cache import CacheWriter
from ..core.contact import ColliderPaths
from ..core.errors import PhysanimError, SimulationError
from ..core.helper_process import can_start, pipes_safe
from ..core.controls import ImpactTracker, SquashSettings, euler_xyz, log_deformation, principal
from ..core.controls.timing import TimeMap
from ..core.particles import ParticleSolver, ParticleState, ParticleSystem, emitter_arrays
from ..core.usd_points import MAX_FLOAT_ID
from . import compat, convert, limits, native_points, timing, usd_process
from .cache_paths import emitter_cache_dir

STREAM = "points"
FLOAT32_MAX = float(np.finfo(np.float32).max)  # the cache stores float32


class ParticleBake:
    """All emitters of a bake, simulated as one particle system.

    Args:
        scene: the scene. emitters: the emitter objects (name order). hashes: per emitter name,
        the inputs hash stored with its cache. stats: counts to add to (births, collisions,
        peak alive). clock: the bake's time map (frame -> simulated time). estimates: per
        emitter name, upper bounds of its particles alive at once and its cache bytes
        (:func:`.budget.emitter_estimates`; missing: unknown).
    """

    def __init__(self, scene, emitters: list, hashes: dict[str, str], stats: dict,
                 clock: TimeMap, estimates: dict[str, tuple[float, float]] | None = None):
        self.scene, self.emitters, self.hashes, self.clock = scene, emitters, hashes, clock
        self.writers: dict[str, CacheWriter] = {}
        self.objects_limit = {ob.name for ob in emitters if ob.physanim.emitter.output == 'OBJECTS'}
        # Emitters whose result plays without the extension: a USD layer per frame as well.
        self.usd = {ob.name for ob in emitters if ob.physanim.emitter.output == 'USD_POINTS'}
        self.usd_extension = native_points.file_extension() if self.usd else ""
        self.usd_processes: dict[str, usd_process.UsdPool | None] = {}
        self._starting: dict[str, usd_process.UsdPool] = {}
        # emitters that will reach the processes' size: theirs start with the bake (last,
        # below), importing pxr while it sets up and simulates the first frames, not when
        # their first large frame waits for them
        large = sorted(name for name in self.usd
                       if (estimates or {}).get(name, (0.0, 0.0))[0] >= usd_process.MIN_POINTS)
        self._pool_size = (usd_process.process_count(len(large) or len(self.usd))
                           if self.usd_extension == ".usdc" else 0)  # (before any folder)
        self.first_frame = 0  # set by start()
        self.births = {ob.name: 0 for ob in emitters}
        self.watch: set[str] = set()  # emitters whose frames Hit the Mark follows
        self.watched: dict = {}  # (emitter, frame) -> (ids, positions, velocities, ages [frames])
        self.stats = stats
        self.system: ParticleSystem | None = None
        try:
            for ob in emitters:
                self.writers[ob.name] = CacheWriter(emitter_cache_dir(scene, ob))
            # squash and stretch: each emitter's particles' last impacts, frame to frame
            self.trackers = {
                ob.name: ImpactTracker(SquashSettings(ob.physanim.emitter.squash,
                                                      ob.physanim.emitter.squash_recovery),
                                       convert.gravity(scene))
                for ob in emitters if ob.physanim.emitter.squash > 0.0}
            for name in large if self._pool_size else ():
                pool = self._spawn(wait=False)
                if pool is not None:
                    self._starting[name] = pool
        except BaseException:  # nothing left behind: no partial folder, no process
            self.abort()
            raise

    @property
    def label(self) -> str:
        """What a failure report calls this system."""
        names = ", ".join(f'"{ob.name}"' for ob in self.emitters)
        return f"particles (emitter{'s' if len(self.emitters) > 1 else ''} {names})"

    @property
    def alive(self) -> int:
        return self.system.state.particle_count if self.system is not None else 0

    # -- set-up ---------------------------------------------------------------------------------
    def prepare(self, extractor, depsgraph, frame: int, colliders: ColliderPaths) -> None:
        """The frozen model at the bake's first frame, its solver and world system."""
        self.model = extractor.build_model(depsgraph, frame)
        s = self.scene.physanim
        self.solver = ParticleSolver(self.model, s.integrator, s.substeps, s.tolerance,
                                     limits.bounds(self.scene), colliders)

    def start(self, frame: int, pre_roll) -> None:
        """The state at the bake's first ``frame``. Births of frame f happen during the interval
        f - 1 -> f, so they show at frame f (emission windows are inclusive: start = end is a
        one-frame burst). When an emitter's window holds the first frame, that interval lies
        before the bake: ``pre_roll()`` gives its inputs, simulated for the particles alone,
        which start the bake with ages up to one frame."""
        self.first_frame = frame
        inputs = pre_roll()
        state = self.model.state(convert.frame_time(self.scene, frame - (inputs is not None)))
        self.system = ParticleSystem(self.solver, state)
        if inputs is not None:
            self.record(self.solver.advance(state, inputs), frame)
        self.write_frame(frame)

    # -- per frame ------------------------------------------------------------------------------
    def record(self, report, frame: int) -> None:
        """Count a frame's births; fail early (before anything is replaced) when the Objects
        output would get too many particles: each particle becomes an object."""
        from .results import MAX_KEYED_OBJECTS

        self.stats["births"] += report.births
        self.stats["collisions"] += report.collisions
        for i, ob in enumerate(self.emitters):
            self.births[ob.name] += report.per_emitter_births[i]
            if ob.name in self.objects_limit and self.births[ob.name] > MAX_KEYED_OBJECTS:
                raise PhysanimError(
                    f"{self.births[ob.name]:,} particles are too many for the Objects output "
                    f"(limit {MAX_KEYED_OBJECTS:,}) — use the Points output or a lower rate",
                    obj=ob.name, frame=frame, kind="emitter")

    def write_frame(self, frame: int, pose: ParticleState | None = None) -> None:
        """Write ``frame``: the particles now, or ``pose`` (a frame shown between sub-steps,
        in slow motion)."""
        state = self.system.state if pose is None else pose
        self._check_cache_range(state, frame)
        for i, ob in enumerate(self.emitters):
            arrays = emitter_arrays(self.model, state, i, frame=frame)
            for key in ("age", "life"):  # frames, as Blender shows them
                arrays[key] = convert.seconds_to_frames(self.scene, arrays[key]).astype(np.float32)
            if ob.name in self.trackers:
                self._squash(ob, self.trackers[ob.name], arrays, frame)
            if ob.name in self.watch:
                self.watched[ob.name, frame] = (arrays["id"], arrays["position"].astype(float),
                                                arrays["velocity"].astype(float),
                                                arrays["age"].astype(float))
            writer = self.writers[ob.name]
            npz = writer.write_frame(STREAM, frame, arrays)
            if ob.name in self.usd:
                self._check_usd_ids(ob, arrays["id"], frame)
                number = native_points.file_number(frame, self.first_frame)
                name = native_points.frame_file_name(number, self.usd_extension)
                process = self._usd_process(ob.name, len(arrays["id"]))
                if process is None:
                    writer.write_file(native_points.STREAM, name, native_points.save_frame,
                                      (arrays, frame))
                else:  # saved from the .npz just queued, by a process on another core
                    writer.write_file(native_points.STREAM, name, process.save, (npz, frame))
        self.stats["peak"] = max(self.stats["peak"], state.particle_count)

    def _usd_process(self, name: str, count: int) -> usd_process.UsdPool | None:
        """The processes writing emitter ``name``'s ``.usdc`` layers once its frames reach
        :data:`usd_process.MIN_POINTS` points; None: the writer thread writes them (smaller
        frames, ``.usda`` text, or no process could start here)."""
        if self.usd_extension != ".usdc" or count < usd_process.MIN_POINTS:
            return self.usd_processes.get(name)
        if name not in self.usd_processes:
            process = self._starting.get(name)
            if process is None:
                process = self._spawn(wait=True)
            else:
                try:
                    process.wait_ready()
                except OSError:  # (they ended themselves)
                    process = None  # the writer thread writes them, as where there is no pxr
                # (on any other exception they stay in _starting, which abort() ends)
                del self._starting[name]
            if process is not None:
                self.writers[name].attach(process)
            self.usd_processes[name] = process
        return self.usd_processes[name]

    def _spawn(self, wait: bool) -> usd_process.UsdPool | None:
        """An emitter's USD processes (:class:`.usd_process.UsdPool`, ``wait`` as there), or
        None where none can start here."""
        site = compat.usd_site()
        if site is None or not self._pool_size or not can_start() \
                or not pipes_safe():
            return None
        try:
            return usd_process.UsdPool(site, self._pool_size, wait=wait)
        except OSError:
            return None

    def _end_starting(self) -> None:
        """End the processes started for emitters whose frames never reached their size (or
        whose bake stops before)."""
        starting, self._starting = self._starting, {}
        usd_process.close_all(starting.values(), kill=True)

    def _squash(self, ob, tracker: ImpactTracker, arrays: dict, frame: int) -> None:
        """The instances' squash and stretch (their volume kept): instance_scale and
        instance_rotation from the velocity and the last impact of each particle."""
        since = np.diff(timing.frame_seconds(self.clock, self.scene, [frame - 1, frame]))[0]
        impact, age = tracker.update(arrays["id"], arrays["velocity"], float(since))
        axes, factors = principal(log_deformation(arrays["velocity"], impact, age,
                                                  tracker.settings))
        scale = arrays["size"][:, None] * factors
        bad = ~(np.abs(scale) <= FLOAT32_MAX).all(axis=1)  # inf, NaN or beyond the cache
        if bad.any():
            k = int(np.argmax(bad))
            speed = float(np.linalg.norm(arrays["velocity"][k]))
            raise PhysanimError(
                f"Squash & Stretch of particle {int(arrays['id'][k])} (moving at {speed:.4g} "
                f"m/s) came to a scale of {factors[k].tolist()} — lower Squash & Stretch",
                obj=ob.name, frame=frame, kind="emitter")
        arrays["instance_scale"] = scale.astype(np.float32)
        arrays["instance_rotation"] = euler_xyz(axes).astype(np.float32)

    @staticmethod
    def _check_usd_ids(ob, ids: np.ndarray, frame: int) -> None:
        """USD point files carry ids as floats: exact up to 2**24 (see core.usd_points)."""
        if len(ids) and int(ids.max()) > MAX_FLOAT_ID:
            raise PhysanimError(
                f"particle id {int(ids.max()):,} is beyond {MAX_FLOAT_ID:,}, the largest id the "
                "Points output's USD files carry exactly — choose Output: Points (Extension), or "
                "lower the rates or bake fewer frames", obj=ob.name, frame=frame, kind="emitter")

    def _check_cache_range(self, state, frame: int) -> None:
        """Every value must be finite and fit the float32 cache: a value beyond it would be
        written as inf (silently) although the float64 simulation is still finite."""
        for what, values, unit in (("position", state.particle_x, "m"),
                                   ("velocity", state.particle_v, "m/s"),
                                   ("size", state.particle_size[:, None], "m"),
                                   ("age", state.particle_age[:, None], "s")):
            # min and max are NaN when any value is: within the range, every value is fine
            if not len(values) or -FLOAT32_MAX <= values.min() and values.max() <= FLOAT32_MAX:
                continue
            bad = ~np.isfinite(values).all(axis=1)
            if bad.any():
                raise self._particle_error(state, int(np.argmax(bad)), frame,
                                           f"{what} became {{value}} — nothing non-finite is "
                                           "ever written to a bake", values)
            big = (np.abs(values) > FLOAT32_MAX).any(axis=1)
            raise self._particle_error(
                state, int(np.argmax(big)), frame,
                f"{what} reached {{value}} {unit}, beyond the cache's float32 range "
                f"(±{FLOAT32_MAX:.3g}) — check the emitter's motion and the forces", values)

    def _particle_error(self, state, i: int, frame: int, message: str, values) -> SimulationError:
        value = np.array2string(values[i], precision=4)
        return SimulationError(f"particle {int(state.particle_id[i])} "
                               f"{message.format(value=value)}",
                               obj=self.model.emitters[int(state.particle_emitter[i])].name,
                               frame=frame, kind="emitter")

    # -- end ------------------------------------------------------------------------------------
    def flush(self) -> None:
        for writer in self.writers.values():
            writer.flush()

    def commit(self, meta: dict) -> dict[str, str]:
        """Swap every emitter's new cache in; returns emitter name -> cache folder."""
        try:
            paths = {ob.name: self.writers[ob.name].commit(dict(meta, emitter=ob.name,
                                                                hash=self.hashes[ob.name]))
                     for ob in self.emitters}
        finally:
            self._end_starting()
        self.writers.clear()
        return paths

    def detach(self) -> None:
        """Stop, keeping the partial caches for a resume; the previous bakes stay as they were."""
        self._stop(CacheWriter.detach)

    def abort(self) -> None:
        """Delete the partial caches; the previous bakes stay as they were."""
        self._stop(CacheWriter.abort)

    def _stop(self, end) -> None:
        """``end(writer)`` for every emitter's cache writer, then no process left running."""
        try:
            for writer in self.writers.values():
                end(writer)
            self.writers.clear()
        finally:
            self._end_starting()
