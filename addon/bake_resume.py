"""The resumable part of a bake (:class:`Resumable`, mixed into :class:`.bake.BakeJob`): what a
checkpoint holds (:mod:`.resume`), and how a new bake continues from one — the frames up to it
linked from the folders it names, every system's state loaded from it."""
from __future__ import annotations

import os
import pickle
import re

from ..core.errors import PhysanimError
from . import inputs_hash, native_points, springs
from . import resume as checkpoint
from .roles import gather

# the number and extension a frame file's name ends with (npz frames, USD layers)
_FRAME_FILE = re.compile(r"(-?\d+)\.(?:npz|usdc|usda)$")

#: What each system's bake wrapper carries from frame to frame, saved in a checkpoint (the core
#: objects among them are shared with the world and pickled together with it).
_RESUMED = {"particles": ("model", "solver", "system", "births", "first_frame", "trackers"),
            "mesh": ("model", "solver", "state", "system", "sample", "asleep_from"),
            "rigid": ("model", "solver", "system", "kinematic", "simulated", "_last",
                      "joint_values")}


class Resumable:
    """Checkpoints of a :class:`.bake.BakeJob` (which holds the systems and the fields used
    here)."""

    def _resume_data(self, only):
        """The scene's checkpoint, checked against the scene; raises when there is none to
        resume or the scene changed."""
        scene = self.scene
        data = checkpoint.load(scene)
        if data is None:
            raise PhysanimError("nothing to resume: no bake of this scene was cut off or "
                                "finished with a checkpoint — bake from the start",
                                obj=scene.name, kind="scene")
        settings = scene.physanim
        end = settings.frame_end
        try:  # the hashes include the frame range: compare at the checkpoint's own
            settings.frame_end = data["frame_end"]
            hashes = self._hash_record(gather(scene, data["only"]))
        finally:
            settings.frame_end = end
        checkpoint.check(scene, data, hashes)
        return data

    def _hash_record(self, roles, all_roles=None) -> dict[str, str]:
        """Every system's inputs hash, keyed as :meth:`partial_folders` keys its folder."""
        all_roles = all_roles or gather(self.scene)
        record = {f"emitter {ob.name}": inputs_hash.emitter_hash(self.scene, ob, all_roles)
                  for ob in roles.emitters}
        record.update({f"spring_mesh {ob.name}": inputs_hash.inputs_hash(
            self.scene, ob, "spring_mesh", all_roles) for ob in roles.spring_meshes})
        if roles.rigid_bodies:
            record["rigid_bodies"] = inputs_hash.rigid_hash(self.scene, roles.rigid_bodies,
                                                            all_roles)
        return record

    def hash_record(self) -> dict[str, str]:
        """The inputs hash of each system still baking."""
        record = {f"emitter {ob.name}": self.hashes[ob.name]
                  for ob in (self.particles.emitters if self.particles is not None else [])}
        record.update({f"spring_mesh {m.ob.name}": self.mesh_hashes[m.ob.name]
                       for m in self.meshes})
        if self.rigid is not None:
            record["rigid_bodies"] = self.rigid_hash
        return record

    def _writers(self) -> dict:
        """Each system's cache writer, keyed as :meth:`partial_folders` keys its folder."""
        out = {}
        if self.particles is not None:
            out.update({f"emitter {name}": w for name, w in self.particles.writers.items()})
        out.update({f"spring_mesh {m.ob.name}": m.writer for m in self.meshes})
        if self.rigid is not None:
            out["rigid_bodies"] = self.rigid.writer
        return out

    def partial_folders(self) -> dict[str, str]:
        """The folder each system's frames are being written to."""
        return {key: str(w.partial_dir) for key, w in self._writers().items()}

    def checkpoint_state(self) -> bytes:
        """Everything the bake carries to the next frame, pickled in one piece (shared objects
        stay shared)."""
        state = {"world": self.world, "sample": self.sample, "colliders": self.colliders,
                 "stats": self.stats, "only": self._only, "tau": self.tau,
                 "particles": self._fields(self.particles, "particles"),
                 "meshes": {m.ob.name: self._fields(m, "mesh") for m in self.meshes},
                 "rigid": self._fields(self.rigid, "rigid")}
        return pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)

    @staticmethod
    def _fields(wrapper, kind: str) -> dict | None:
        if wrapper is None:
            return None
        return {name: getattr(wrapper, name) for name in _RESUMED[kind]}

    def _save_checkpoint(self, finished: bool = False, folders=None, state=None,
                         frame: int | None = None) -> None:
        if self._no_checkpoint is not None:
            return
        if not self._aside:
            # the scene's checkpoint (a finished bake's, or a cut-off one's with its partial
            # folders) is kept until this bake finishes: a failed bake puts it back
            checkpoint.set_aside(self.scene)
            self._aside = True
        # A checkpoint names only frames whose files are whole on disk: a process killed right
        # after it must not leave a frame half written that a resume would keep.
        for writer in self._writers().values():
            writer.flush()
        try:
            self.checkpoints.save(self, finished, folders, state, frame)
        except (pickle.PicklingError, TypeError, AttributeError) as exc:
            self._checkpoint_failed(exc)

    def _checkpoint_settled(self, kept: bool) -> None:
        """The bake is over: the checkpoint it set aside goes when it finished or was cut off
        (``kept``: its own checkpoint stands), and is the scene's again when it failed."""
        if self._aside:  # (set before this bake's first checkpoint: none without it)
            checkpoint.drop_previous(self.scene) if kept else checkpoint.put_back(self.scene)
            self._aside = False

    def _checkpoint_failed(self, exc: Exception) -> None:
        """Something in the state cannot be saved: the bake goes on, without checkpoints (it
        cannot be resumed or extended), and says so."""
        self._no_checkpoint = f"no checkpoint ({exc}): this bake cannot be resumed or extended"
        print(f"PhysAnim: {self._no_checkpoint}", flush=True)

    def _restore(self, data: dict) -> None:
        """Continue from ``data``: the frames up to its checkpoint linked from its folders into
        this bake's, every system's state loaded from it."""
        frame = data["frame"]
        samples = frame - self.frame_start + 1
        state = checkpoint.state_of(data)
        # the first frame's files, queued on the writer threads, land before the frames
        # resumed from are linked over them (both touched one file at once: USD could not
        # open it for writing)
        for writer in self._writers().values():
            writer.flush()
        folders = self.partial_folders()
        missing = sorted(set(data["folders"]) - set(folders))
        if missing:
            raise PhysanimError(f"cannot resume: {', '.join(missing)} did not bake again (see "
                                "the report) — bake from the start", obj=self.scene.name,
                                kind="scene")
        last_file = native_points.file_number(frame, self.frame_start)

        def baked(rel: str) -> bool:  # a frame file up to the checkpoint (the PC2 is cut apart)
            usd = rel.startswith(native_points.STREAM + os.sep)
            return not rel.endswith(".pc2") and _numbered_within(rel, last_file if usd else frame)

        for key, source in data["folders"].items():
            if not os.path.isdir(source):
                raise PhysanimError(f'cannot resume: the frames of {key} are gone ("{source}") '
                                    "— bake from the start", obj=self.scene.name, kind="scene")
            checkpoint.link_frames(source, folders[key], baked)
        for mesh in self.meshes:
            source = os.path.join(data["folders"][f"spring_mesh {mesh.ob.name}"],
                                  springs.CACHE_FILE)
            mesh.pc2.close()
            mesh.pc2 = checkpoint.cut_pc2(source, mesh.pc2.path, samples)
        self.world, self.sample, self.colliders = (state["world"], state["sample"],
                                                   state["colliders"])
        self.stats.update(state["stats"])
        for wrapper, fields in ((self.particles, state["particles"]),
                                (self.rigid, state["rigid"]),
                                *((m, state["meshes"][m.ob.name]) for m in self.meshes)):
            for name, value in (fields or {}).items():
                setattr(wrapper, name, value)
        if self.particles is not None:
            self.particles.stats = self.stats
        for mesh in self.meshes:
            mesh.colliders = self.colliders
        self.frame = frame
        self.tau = state.get("tau", frame)  # the simulated time reached (Time Scale)
        self.scene.frame_set(frame)


def _numbered_within(name: str, last: int) -> bool:
    """Whether ``name`` is a frame file (its number right before a frame file's extension: not
    a writer's temporary file, as USD leaves one named ``points_000021.8ZnMNG`` when the
    process saving the layer is killed) whose number is at most ``last``."""
    numbered = _FRAME_FILE.search(os.path.basename(name))
    return numbered is not None and int(numbered.group(1)) <= last

