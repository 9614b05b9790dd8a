"""A bake as a resumable job: prepare -> step (one frame each) -> finish | abort.

The operator drives it synchronously (background, scripts, CLI) or from a modal timer (UI, with
progress and ESC). One frame (:meth:`BakeJob.step`), as a table of contents:

    sample      the scene over the interval: colliders, forces, emitters (extract)
    own inputs  what each system alone reads: emitter values, a spring mesh's pins and targets
    simulate    the core world stepper advances every system together (core/world.py)
    write       each system's frame into its new cache folder

Each system (the particles of all emitters, each spring mesh) streams into a fresh cache
folder; :meth:`BakeJob.finish` swaps them in and writes native results, :meth:`BakeJob.abort`
deletes the partial folders so the previous bake stays exactly as it was. A system that fails
is dropped — its previous bake kept — and the others go on; only when none is left does the
failure stop the bake.
"""
from __future__ import annotations

import os
import pickle
import time
from dataclasses import replace


from ..core.contact import ColliderPaths
from ..core.errors import PhysanimError
from ..core.world import World
from . import budget, convert, extract, follow, inputs_hash, limits, rigid, rigid_keys
from . import aim as aim_solver
from . import resume as checkpoint
from . import allocator, blas, springs, timing
from .bake_failures import Failures
from .bake_resume import Resumable
from .cache_paths import relative_path
from .particles_bake import STREAM, ParticleBake
from .roles import Roles, check_exclusive, gather

class BakeJob(Resumable, Failures):
    """Bake every (or the chosen) emitter and spring mesh of a scene, one frame per :meth:`step`.

    Args:
        context: Blender context. only: names of emitters and spring meshes to bake (None: all).
        resume: go on from the scene's checkpoint (:mod:`.resume`): a cut-off bake continues
            where it stopped, a finished one is extended to the scene's frame end.
        checkpoint_every: seconds of baking between checkpoints (0: every frame; None:
            :func:`.resume.interval`).
        aim: first solve the launch of rigid bodies with a target (:mod:`.aim`).
    """

    def __init__(self, context, only: set[str] | None = None, resume: bool = False,
                 checkpoint_every: float | None = None, aim: bool = True):
        self.scene = context.scene
        self.checkpoints = checkpoint.Checkpoints(checkpoint_every)
        self._resume_from = self._resume_data(only) if resume else None
        if self._resume_from is not None:
            only = self._resume_from["only"]
        self._aside = False  # set the scene's checkpoint aside for its own (resume.set_aside)
        self._keep_partial = False  # suspended: the partial folders stay for a resume
        self._no_checkpoint: str | None = None  # why this bake cannot save checkpoints
        self.view_layer = context.view_layer
        self.settings = self.scene.physanim
        self.original_frame = self.scene.frame_current
        self._only = only
        self.roles = self._roles(only)
        limits.check_scene(self.scene, self.frame_start, self.frame_end)
        # frame -> simulated time (Time Scale); the simulation steps whole frames of its own
        self.clock = timing.time_map(self.scene, self.frame_start, self.frame_end)
        # (per emitter: its peak of particles alive and its cache bytes, upper bounds)
        self.estimates = budget.check_budget(self.scene, self.roles, float(self.clock.scale.max()))
        for ob in self.roles.followers:  # refused before anything changes
            follow.check(ob, self.frame_start)
        # hit the mark: bodies with a target get the launch that reaches it (scratch bakes)
        self.aim_notes = (aim_solver.solve(context, self.roles, self.frame_start, self.frame_end,
                                           self.clock)
                          if aim and self._resume_from is None else [])
        self.frame = self.frame_start  # the last frame written
        self.tau = self.frame_start  # the simulated time reached, in frame lengths
        self._before_end = (None, self.frame_start)  # (state, frame) before the last step
        self.started = time.perf_counter()
        self.failures: list[tuple[str, str]] = []  # (system, message) of systems that failed
        self._unprepared = 0  # spring meshes not built yet: a failure before them is not the last
        self.stats = {"births": 0, "collisions": 0, "peak": 0}  # the particles', kept if they fail
        self.colliders = ColliderPaths()  # every system's colliders, kept for the whole run
        self.world = World([], self.colliders)
        self.particles: ParticleBake | None = None
        self.meshes: list[springs.SpringMeshBake] = []
        self.rigid: rigid.RigidBake | None = None
        self.breaks: list[str] = []  # which constraints broke, at which frames
        from . import results

        results.suspend_refresh(self.scene)  # our own frame changes must not reload old bakes
        # the bake reads each spring mesh without its previous cache playing on top
        self.suspended = {ob.name: springs.suspend_modifier(ob) for ob in self.roles.spring_meshes}
        # ... and each rigid body from its own animation, not an earlier bake's keys
        self.rigid_suspended = {ob.name: rigid_keys.suspend(ob) for ob in self.roles.rigid_bodies}
        # freed arrays reused (glibc) and BLAS on this thread (a busy core stalls OpenBLAS's
        # own: addon/blas.py) while the bake runs; given back by finish() and abort()
        self.memory = allocator.Hold(allocator.GLIBC, blas.OPENBLAS)
        try:
            self._prepare(context)
            if self._resume_from is not None:
                self._restore(self._resume_from)
        except BaseException:
            self.abort()
            raise

    # -- set-up ---------------------------------------------------------------------------------
    def _roles(self, only: set[str] | None) -> Roles:
        roles = gather(self.scene, only)
        if not roles:
            raise PhysanimError("nothing to bake: no object has a PhysAnim emitter, spring "
                                "mesh or rigid body enabled", obj=self.scene.name, kind="scene")
        check_exclusive(roles)
        self.frame_start = self.settings.frame_start
        self.frame_end = self.settings.frame_end
        if self.frame_end < self.frame_start:
            raise PhysanimError(f"frame end {self.frame_end} is before frame start {self.frame_start}",
                                obj=self.scene.name, kind="scene")
        return roles

    def _prepare(self, context) -> None:
        """Open the caches, build each system at the first frame and write that frame."""
        all_roles = gather(self.scene)
        self.hashes = {ob.name: inputs_hash.emitter_hash(self.scene, ob, all_roles)
                       for ob in self.roles.emitters}
        self.mesh_hashes = {ob.name: inputs_hash.inputs_hash(self.scene, ob, "spring_mesh",
                                                             all_roles)
                            for ob in self.roles.spring_meshes}
        self.rigid_hash = inputs_hash.rigid_hash(self.scene, self.roles.rigid_bodies, all_roles)
        if self.roles.emitters:
            self.particles = ParticleBake(self.scene, self.roles.emitters, self.hashes, self.stats,
                                          self.clock, self.estimates)
        self.extractor = extract.Extractor(self.scene, self.roles)
        self.scene.frame_set(self.frame_start)
        depsgraph = context.evaluated_depsgraph_get()
        if self.roles.rigid_bodies:
            self._prepare_rigid(depsgraph)
        for i, ob in enumerate(self.roles.spring_meshes):
            self._unprepared = len(self.roles.spring_meshes) - i - 1  # still to come
            self._prepare_mesh(ob, depsgraph)
        self._unprepared = 0
        if self.particles is not None:
            with self._system(self.particles):
                self.particles.prepare(self.extractor, depsgraph, self.frame_start,
                                       self.colliders)
        self.sample = self.extractor.sample(depsgraph, self.frame_start, emitters=False)
        self.sample.emitters = self._emitter_read(
            lambda: self.extractor.sample_emitters(depsgraph, self.frame_start))
        if self.particles is not None:
            with self._system(self.particles):
                self.particles.start(self.frame_start, self._pre_roll)
                self.world.systems.insert(0, self.particles.system)

    def _prepare_rigid(self, depsgraph) -> None:
        """The rigid bodies step first: the others may meet them within the same frame."""
        self._unprepared += 1
        bake = rigid.RigidBake(self.scene, self.roles.rigid_bodies, self.rigid_hash,
                               self.roles.joints)
        self.rigid = bake
        with self._system(bake):
            bake.prepare(depsgraph, self.frame_start, self.colliders)
            self.world.systems.insert(0, bake.system)
        self._unprepared -= 1

    def _prepare_mesh(self, ob, depsgraph) -> None:
        mesh = None
        try:
            mesh = springs.SpringMeshBake(self.scene, ob, self.frame_start, self.colliders)
            mesh.prepare(depsgraph, self.frame_start)
        except (PhysanimError, ValueError) as exc:
            if mesh is not None:
                mesh.abort()
            self._failed(f'spring mesh "{ob.name}"', ob.name, exc)
            return
        self.meshes.append(mesh)
        self.world.systems.append(mesh.system)

    def _pre_roll(self):
        """Inputs of the interval before the first frame, for emitters whose window holds the
        first frame (their births of it happen then); None when no emitter is active."""
        s = self.frame_start
        if not any(values["active"] for *_, values in self.sample.emitters):
            return None
        frame = self.clock.frame(s - 1)
        timing.go_to(self.scene, frame)
        before = self.extractor.sample(self.view_layer.depsgraph, frame, tau=s - 1)
        inputs, self.sample = self._interval(s - 1, before)
        return inputs

    # -- progress -------------------------------------------------------------------------------
    @property
    def alive(self) -> int:
        """Particles alive now (0 once the particle system failed)."""
        return self.particles.alive if self.particles is not None else 0

    @property
    def contents(self) -> str:
        """What is being simulated, for progress lines: "12,000 particles, 40 rigid bodies"."""
        parts = [f"{self.alive:,} particles"] if self.particles is not None else []
        if self.rigid is not None:
            parts.append(_counted(len(self.rigid.objects), "rigid body", "rigid bodies"))
        if self.meshes:
            parts.append(_counted(len(self.meshes), "spring mesh", "spring meshes"))
        return ", ".join(parts) or "nothing left to simulate"

    @property
    def total_frames(self) -> int:
        return self.frame_end - self.frame_start

    @property
    def progress(self) -> float:
        return (self.frame - self.frame_start) / max(1, self.total_frames)

    # -- one frame ------------------------------------------------------------------------------
    def step(self, context) -> bool:
        """Simulate and write the next frame. Returns True when the bake has reached its end."""
        if self.frame >= self.frame_end:
            return True
        # the frames this simulation frame shows (in slow motion several, each at a fraction
        # of it; at double speed every other one none), then the frame itself
        shown = self.clock.frames_in(self.tau, self.frame, self.frame_end)
        if shown and shown[-1][0] == self.frame_end and self._no_checkpoint is None \
                and self.clock.tau(self.frame_end) < self.tau + 1.0 - 1e-9:
            # the last step runs past the frame end: a later extension starts from before it
            try:
                self._before_end = (self.checkpoint_state(), self.frame)
            except (pickle.PicklingError, TypeError, AttributeError) as exc:
                self._checkpoint_failed(exc)
        inputs, sample = self._interval(self.tau, self.sample)
        world = inputs.world
        samples = tuple(w for _, w in shown if w < 1.0)
        if samples:
            world = replace(world, samples=samples)
        own, mesh_samples = self._own_inputs(inputs, sample.frame)
        report = self.world.advance(world, own)
        for system, exc in report.failed:
            self._drop(self._channel(system), exc)
        self._write(report, mesh_samples, shown, sample.frame)
        self.sample = sample
        self.tau += 1
        if shown:
            self.frame = shown[-1][0]
        if self.frame < self.frame_end and self.checkpoints.due():
            self._save_checkpoint()
        return self.frame >= self.frame_end

    def _interval(self, tau: int, start):
        """Core inputs for the simulation frame ``tau`` -> ``tau + 1`` (simulated time in frame
        lengths) from the sample ``start`` at its beginning; leaves the scene at the frame
        showing its end. Returns (inputs, sample there)."""
        between = []
        substeps = self.settings.substeps
        depsgraph = self.view_layer.depsgraph
        self._rigid_between = []
        for k in range(1, substeps):  # sub-frame motion keys: one per sub-step boundary
            timing.go_to(self.scene, self.clock.frame(tau + k / substeps))
            between.append(self.extractor.sample_motion(emitters=False))
            between[-1][0].extend(self._emitter_read(self.extractor.emitter_motion))
            if self.rigid is not None:
                with self._system(self.rigid):
                    self._rigid_between.append(
                        self.rigid.kinematic_matrices(self.scene.frame_current_final))
        frame = self.clock.frame(tau + 1)
        timing.go_to(self.scene, frame)
        end = self.extractor.sample(depsgraph, frame, emitters=False, tau=tau + 1)
        end.emitters = self._emitter_read(lambda: self.extractor.sample_emitters(
            depsgraph, frame, since=start.frame))
        return self.extractor.inputs(start, end, between), end

    def _own_inputs(self, inputs, nxt: float) -> tuple[dict, dict]:
        """Each system's own input for the interval: the emitters' values for the particles,
        a spring mesh's pins and targets at ``nxt`` (read now, the scene being there)."""
        own, samples = {}, {}
        if self.particles is not None:
            own[self.particles.system] = inputs.drive
        if self.rigid is not None:
            with self._system(self.rigid):
                own[self.rigid.system] = self.rigid.begin(nxt, self._rigid_between)
        for mesh in list(self.meshes):
            with self._system(mesh):
                samples[mesh.ob.name] = mesh.read(self.view_layer.depsgraph, nxt)
                own[mesh.system] = mesh.drive(samples[mesh.ob.name])
        return own, samples

    def _write(self, report, mesh_samples: dict, shown: list, end: float) -> None:
        """Write the ``shown`` frames (frame, fraction of the simulation frame) of each system;
        ``end``: the scene frame at the simulation frame's end (messages)."""
        if self.rigid is not None:
            self.rigid.centres = {}
            with self._system(self.rigid):
                for frame, pose in self._poses(report, self.rigid.system, shown):
                    self.rigid.write_frame(frame, pose)
        if self.particles is not None:
            with self._system(self.particles):
                self.particles.record(report.reports[self.particles.system], end)
                for frame, pose in self._poses(report, self.particles.system, shown):
                    self.particles.write_frame(frame, pose)
        for mesh in list(self.meshes):
            with self._system(mesh):
                mesh.end_frame(mesh_samples[mesh.ob.name])
        poses = {mesh: self._poses(report, mesh.system, shown) for mesh in self.meshes}
        for k, (frame, w) in enumerate(shown):
            if w < 1.0 and poses:  # the object-space cache needs each mesh's matrix there
                timing.go_to(self.scene, frame)
            for mesh in list(self.meshes):
                with self._system(mesh):
                    mesh.write(frame, poses[mesh][k][1])

    @staticmethod
    def _poses(report, system, shown: list) -> list:
        """(frame, pose) per shown frame: the pose the world sampled for a frame inside the
        simulation frame, None (the state itself) for the frame at its end."""
        inner = iter(report.poses.get(system, ()))
        return [(frame, next(inner) if w < 1.0 else None) for frame, w in shown]

    # -- end ------------------------------------------------------------------------------------
    def finish(self, context) -> str:
        """Swap the new caches in and point every result at them. Returns a summary."""
        from . import results

        self.memory.end()  # the simulation is over

        meta = {"frame_start": self.frame_start, "frame_end": self.frame_end,
                "fps": convert.fps(self.scene), "kind": "particles"}
        final_state = None  # the last frame's, for a later extension
        if self._no_checkpoint is None:
            try:
                final_state = self.checkpoint_state()
            except (pickle.PicklingError, TypeError, AttributeError) as exc:
                self._checkpoint_failed(exc)
        final_record = self.hash_record()
        self.colliders.release()
        for mesh in self.meshes:  # every frame on disk before any bake is swapped in
            mesh.close()
            mesh.writer.flush()
        if self.particles is not None:
            self.particles.flush()
        if self.rigid is not None:
            self.rigid.flush()
        keys = []  # computed and checked (Squash & Stretch) before any cache is swapped in:
        if self.rigid is not None:  # a failure there drops the rigid bodies, keeping their keys
            with self._system(self.rigid):
                keys = rigid_keys.plan_keys(
                    self.scene, self.rigid.objects,
                    os.path.join(self.rigid.writer.partial_dir, rigid.STREAM), self.frame_start,
                    self.frame_end, self.rigid.simulated, self.clock, self.rigid.model.body_com)
        emitters = self.particles.emitters if self.particles is not None else []
        paths = self.particles.commit(meta) if self.particles is not None else {}
        mesh_paths = {mesh.ob.name: mesh.commit(dict(meta, kind="spring_mesh", object=mesh.ob.name,
                                                     hash=self.mesh_hashes[mesh.ob.name]))
                      for mesh in self.meshes}
        rigid_path = self.rigid.commit(dict(meta, hash=self.rigid_hash)) \
            if self.rigid is not None else None
        results.resume_refresh(self.scene)
        if self.rigid is not None:
            rigid_keys.write_keys(keys)
            for ob in self.rigid.objects:
                ob.physanim.rigid_body.bake_hash = self.rigid_hash
            self.breaks = self.rigid.record_breaks()
            self.rigid_suspended.clear()
        folders = {f"emitter {name}": str(path) for name, path in paths.items()}
        folders.update({f"spring_mesh {name}": str(path) for name, path in mesh_paths.items()})
        if rigid_path is not None:
            folders["rigid_bodies"] = str(rigid_path)
        # a finished bake is extended from its last state — or, when its last simulation frame
        # ran past the frame end (a Time Scale), from the state before it, so the frames that
        # one shows past the end are simulated when the bake is extended
        state_at = (final_state, self.frame)
        if abs(self.tau - self.clock.tau(self.frame_end)) > 1e-9:
            state_at = self._before_end
        if state_at[0] is not None and set(folders) == set(final_record):
            self._save_checkpoint(finished=True, folders=folders, state=state_at[0],
                                  frame=state_at[1])
        else:  # the scene's checkpoint (this bake's partial folders, or an earlier bake's)
            checkpoint.discard(self.scene)  # no longer describes what is baked
            self._aside = False
        self._checkpoint_settled(kept=True)
        for ob in emitters:
            results.attach(context, self.scene, ob,
                           relative_path(os.path.join(paths[ob.name], STREAM)),
                           self.frame_start, self.frame_end, self.hashes[ob.name])
        for mesh in self.meshes:
            ob = mesh.ob
            springs.attach(ob, relative_path(os.path.join(mesh_paths[ob.name], springs.CACHE_FILE)),
                           self.frame_start, self.mesh_hashes[ob.name], self.suspended.get(ob.name))
        self.suspended.clear()
        # last: followers trail parents that may have just been baked
        follow.bake(self.scene, self.roles.followers, self.frame_start, self.frame_end,
                    self.clock)
        all_roles = gather(self.scene)
        follow_hashes = [inputs_hash.follow_hash(self.scene, ob, all_roles)
                         for ob in self.roles.followers]
        for ob, digest in zip(self.roles.followers, follow_hashes):
            ob.physanim.follow.bake_hash = digest
        self.scene.frame_set(self.original_frame)
        self.settings.bake_hash = inputs_hash.scene_hash(
            [*(self.hashes[ob.name] for ob in emitters),
             *(self.mesh_hashes[mesh.ob.name] for mesh in self.meshes),
             *([self.rigid_hash] if self.rigid is not None else []), *follow_hashes])
        return self._summary(len(emitters))

    def _summary(self, emitters: int) -> str:
        took = time.perf_counter() - self.started
        stats = self.stats
        # (emitters named only when the bake had some: "0 emitter(s)" says they failed)
        parts = [f"{emitters} emitter(s)"] if self.roles.emitters else []
        if self.meshes:
            parts.append(_counted(len(self.meshes), "spring mesh", "spring meshes"))
        if self.rigid is not None:
            parts.append(_counted(len(self.rigid.objects), "rigid body", "rigid bodies"))
            if self.rigid.constraints:
                parts.append(f"{len(self.rigid.constraints)} constraint(s)")
        if self.roles.followers:
            parts.append(f"{len(self.roles.followers)} follower(s)")
        births = (f": {stats['births']:,} births, peak {stats['peak']:,} alive" if emitters
                  else "")
        info = (f"baked {', '.join(parts)}, frames {self.frame_start}-{self.frame_end}"
                f"{births}, {took:.2f} s")
        notes = [*self.breaks, *springs.rest_notes(self.meshes), *(self.aim_notes or [])]
        if notes:
            info += "; " + "; ".join(notes)
        self.settings.bake_info = info
        return info

    def suspend(self) -> None:
        """Cancelled (Esc, Ctrl+C): keep the frames baked so far and a checkpoint, so Resume
        can go on; restore the scene as :meth:`abort` does. The previous bake is untouched."""
        try:
            for mesh in self.meshes:
                mesh.writer.flush()
            if self.particles is not None:
                self.particles.flush()
            if self.rigid is not None:
                self.rigid.flush()
            self._save_checkpoint()
        except BaseException:  # whatever a writer thread raised: nothing kept, all restored
            self.abort()
            raise
        self._keep_partial = True
        self.abort()

    def abort(self) -> None:
        """Delete partial caches and restore the frame; the previous bake is untouched."""
        from . import results

        self.memory.end()

        keep = self._keep_partial
        self._checkpoint_settled(kept=keep)  # a failed bake's checkpoint named its partial folders
        self.colliders.release()
        for mesh in self.meshes:
            mesh.detach() if keep else mesh.abort()
        if self.particles is not None:
            self.particles.detach() if keep else self.particles.abort()
        for ob in self.roles.spring_meshes:
            springs.restore_modifier(ob, self.suspended.get(ob.name))
        self.suspended.clear()
        if self.rigid is not None:
            self.rigid.detach() if keep else self.rigid.abort()
        self._restore_rigid()
        results.resume_refresh(self.scene)
        if self.scene.frame_current != self.original_frame:
            self.scene.frame_set(self.original_frame)


def run(context, only: set[str] | None = None, on_frame=None,
        resume: bool = False) -> tuple[str, str | None]:
    """Bake synchronously. ``on_frame(job)`` is called once for each frame reached (progress,
    logging); ``resume``: go on from the scene's checkpoint (see :class:`BakeJob`).

    Returns the summary line and the failure report of systems that failed while others baked
    (None when none failed); raises PhysanimError/OSError/ValueError after aborting, leaving
    the previous bake intact, when nothing could bake. Ctrl+C (KeyboardInterrupt) keeps what
    baked so far for a later resume.
    """
    job = BakeJob(context, only, resume)
    reported = []

    def report() -> None:  # once per frame shown (slowed down, several steps end in one)
        if on_frame is not None and reported[-1:] != [job.frame]:
            reported.append(job.frame)
            on_frame(job)
    try:
        report()
        while not job.step(context):
            report()
        report()
        info = job.finish(context)
        return info, job.failure_report(info)
    except KeyboardInterrupt:
        job.suspend()
        raise
    except BaseException:
        job.abort()
        raise


def _counted(count: int, one: str, many: str) -> str:
    """A count and its noun: "1 rigid body", "1,000 rigid bodies"."""
    return f"{count:,} {one if count == 1 else many}"
