"""Bakes that resume or extend: a checkpoint of the whole simulation, saved as the bake goes.

A checkpoint is one pickle of everything the bake carries from frame to frame — the core world
(every system, its solver with warm starts and caches, its state, its random generators), the
last scene sample and the colliders' paths — with the frame it belongs to, the bake's frame
range, the inputs hash of each system and the folder each system's frames are in. It lives in
``<cache>/<scene>/.resume/checkpoint.pkl`` and is replaced (atomically) at most every
:data:`EVERY_SECONDS` of baking, when a bake is cancelled, and when one finishes.

- A bake cut off (Esc, Ctrl+C, a killed process) keeps its partial folders; **Resume** builds
  the bake again, links the frames up to the checkpoint from those folders into new ones, loads
  the checkpoint and goes on. The result is bit-identical to a bake that was never cut off.
- A finished bake's checkpoint is its last frame in its committed folders: **Resume** with a
  later frame end extends it the same way.
- The scene must be as it was (every system's inputs hash, the frame range apart from its end):
  otherwise resuming is refused, naming what changed. A fresh bake replaces the checkpoint and
  the partial folders it kept once it finishes or is cut off; until then they are set aside, and
  a bake that fails puts them back as they were (Resume still goes on from them).
"""
from __future__ import annotations

import os
import pickle
import shutil
import time
from pathlib import Path

from ..core.errors import PhysanimError
from ..core.pc2 import Pc2Writer
from .cache_paths import cache_root, safe_name

CHECKPOINT = "checkpoint.pkl"
PREVIOUS = "checkpoint.previous.pkl"  # the checkpoint a running bake replaced (set_aside)
#: The extension's own package (``bl_ext.<repository>.physanim``): checkpoints name classes by
#: module, and another machine (a farm node) may have installed PhysAnim from another repository.
PACKAGE = __name__.rsplit(".addon.", 1)[0]
#: Seconds of baking between checkpoints: the work a cut-off bake can lose (each checkpoint costs
#: a pickle of the state). PHYSANIM_CHECKPOINT_SECONDS overrides it (:func:`interval`).
EVERY_SECONDS = 10.0
#: Bumped when what a checkpoint holds changes shape (2: an emitter's particle constraints carry
#: their wire; 3: a spring mesh's solver keeps its tearing lengths and its angular springs their
#: last geometry; 4: the rigid-body solver keeps its candidate pairs), so an older checkpoint is
#: not resumed but baked afresh.
FORMAT = 4


def folder(scene) -> Path:
    return Path(cache_root(scene)) / safe_name(scene.name) / ".resume"


def load(scene) -> dict | None:
    """The scene's checkpoint, or None (none, unreadable, or from another format)."""
    try:
        path = folder(scene) / CHECKPOINT
    except PhysanimError:  # no cache folder (an unsaved file with a '//' cache)
        return None
    return _read(path)


def _read(path: Path) -> dict | None:
    if not path.is_file():
        return None
    try:
        with open(path, "rb") as handle:
            data = pickle.load(handle)
    except (OSError, pickle.UnpicklingError, EOFError, AttributeError, ImportError):
        return None
    return data if isinstance(data, dict) and data.get("format") == FORMAT else None


def status(scene) -> tuple[str, bool] | None:
    """(what the panel says of the checkpoint: which frames are cached and what Resume would
    do, whether Resume can run), or None without a checkpoint."""
    data = load(scene)
    if data is None:
        return None
    first, last, end = data["frame_start"], data["frame"], data["frame_end"]
    target = scene.physanim.frame_end
    if data["finished"]:
        if target > end:
            return f"Frames {first}-{end} cached: Resume extends the bake to {target}", True
        return f"Frames {first}-{end} cached", False
    return (f"Frames {first}-{last} of {first}-{end} cached (cut off): Resume continues from "
            f"frame {last}", True)


def release(data: dict) -> None:
    """Delete the partial folders a checkpoint kept (never a finished bake's folders)."""
    for path in data["folders"].values():
        if ".partial-" in os.path.basename(path):
            shutil.rmtree(path, ignore_errors=True)


def discard(scene) -> None:
    """Forget the checkpoint (and one set aside); delete the partial folders they kept (never a
    finished bake's)."""
    try:
        target = folder(scene)
    except PhysanimError:
        return
    _forget(target / CHECKPOINT)
    _forget(target / PREVIOUS)
    shutil.rmtree(target, ignore_errors=True)


def set_aside(scene) -> None:
    """A bake is about to save its first checkpoint: the scene's checkpoint so far is kept
    aside, byte for byte with the partial folders it names, until the bake finishes
    (:func:`drop_previous`) or fails (:func:`put_back`). One set aside by a bake whose process
    was killed is superseded by the checkpoint that bake left: it goes."""
    target = folder(scene)
    _forget(target / PREVIOUS)
    if (target / CHECKPOINT).is_file():
        os.replace(target / CHECKPOINT, target / PREVIOUS)


def put_back(scene) -> None:
    """A bake that set the checkpoint aside failed: its own checkpoint and the partial folders
    it named go, the one set aside is the scene's again."""
    target = folder(scene)
    _forget(target / CHECKPOINT)
    if (target / PREVIOUS).is_file():
        os.replace(target / PREVIOUS, target / CHECKPOINT)
    else:
        shutil.rmtree(target, ignore_errors=True)


def drop_previous(scene) -> None:
    """A bake that set the checkpoint aside finished or was cut off: the one set aside no longer
    describes anything baked — it goes, with its partial folders (a resumed bake linked the
    frames it needed)."""
    _forget(folder(scene) / PREVIOUS)


def _forget(path: Path) -> None:
    """Delete the checkpoint file ``path`` (if any) and the partial folders it names."""
    data = _read(path)
    if data is not None:
        release(data)
    path.unlink(missing_ok=True)


def interval() -> float:
    """Seconds between checkpoints: PHYSANIM_CHECKPOINT_SECONDS when it is a number >= 0 (e.g.
    often on preemptible farm nodes), else :data:`EVERY_SECONDS`."""
    try:
        seconds = float(os.environ.get("PHYSANIM_CHECKPOINT_SECONDS", EVERY_SECONDS))
    except ValueError:
        return EVERY_SECONDS
    return seconds if seconds >= 0.0 else EVERY_SECONDS


class Checkpoints:
    """Saves a job's checkpoints: after a frame when :meth:`due`, and at the end or on cancel.
    ``every``: seconds between checkpoints (0: every frame)."""

    def __init__(self, every: float | None = None):
        every = interval() if every is None else every
        self.every = every
        self.last = time.perf_counter()

    def due(self) -> bool:
        return time.perf_counter() - self.last >= self.every

    def save(self, job, finished: bool, folders: dict[str, str] | None = None,
             state: bytes | None = None, frame: int | None = None) -> None:
        """Write the checkpoint of ``job`` at its frame (``state``: its pickled state, taken
        earlier at ``frame``, default the job's; ``folders``: where its frames are, default its
        partial folders)."""
        frame = job.frame if frame is None else frame
        data = {"format": FORMAT, "package": PACKAGE, "frame": frame, "frame_start": job.frame_start,
                "frame_end": job.frame_end, "finished": finished, "hashes": job.hash_record(),
                "only": sorted(job._only) if job._only is not None else None,
                "folders": folders or job.partial_folders(),
                "state": state if state is not None else job.checkpoint_state()}
        target = folder(job.scene)
        target.mkdir(parents=True, exist_ok=True)
        partial = target / f".{CHECKPOINT}.tmp"
        with open(partial, "wb") as handle:
            pickle.dump(data, handle, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(partial, target / CHECKPOINT)
        self.last = time.perf_counter()


class _Unpickler(pickle.Unpickler):
    """Finds PhysAnim's classes under this installation's package, whatever the package was
    where the checkpoint was written."""

    def __init__(self, file, package: str):
        super().__init__(file)
        self.package = package

    def find_class(self, module: str, name: str):
        if module == self.package or module.startswith(self.package + "."):
            module = PACKAGE + module[len(self.package):]
        return super().find_class(module, name)


def state_of(data: dict):
    """The pickled simulation state of a checkpoint, loaded."""
    import io

    return _Unpickler(io.BytesIO(data["state"]), data["package"]).load()


def check(scene, data: dict, hashes: dict) -> None:
    """Refuse to resume when the scene is no longer what the checkpoint was baked from."""
    s = scene.physanim
    if s.frame_start != data["frame_start"]:
        raise PhysanimError(f"the bake started at frame {data['frame_start']}, the scene now at "
                            f"{s.frame_start} — bake from the start", obj=scene.name,
                            kind="scene")
    if s.frame_end < data["frame"] or (data["finished"] and s.frame_end == data["frame_end"]):
        raise PhysanimError(f"nothing to resume: frames {data['frame_start']}-{data['frame']} "
                            f"are cached and the frame end is {s.frame_end}", obj=scene.name,
                            kind="scene")
    changed = sorted(name for name in set(data["hashes"]) | set(hashes)
                     if data["hashes"].get(name) != hashes.get(name))
    if changed:
        raise PhysanimError(f"the scene changed since frames {data['frame_start']}-"
                            f"{data['frame']} were baked ({', '.join(changed)}) — bake from the "
                            "start", obj=scene.name, kind="scene")


def link_frames(source: str, target: str, keep) -> None:
    """Hard-link (or copy) the files of ``source`` into ``target`` (same layout), except those
    for which ``keep(relative path)`` is False; a PC2 file is cut to its samples kept."""
    for root, _dirs, files in os.walk(source):
        relative = os.path.relpath(root, source)
        for name in files:
            rel = os.path.normpath(os.path.join(relative, name))
            if name == "meta.json" or not keep(rel):
                continue
            destination = os.path.join(target, rel)
            os.makedirs(os.path.dirname(destination), exist_ok=True)
            if os.path.exists(destination):
                os.remove(destination)
            try:
                os.link(os.path.join(root, name), destination)
            except OSError:  # another file system, or no hard links there
                shutil.copy2(os.path.join(root, name), destination)


def cut_pc2(source: str, writer_path: str, samples: int) -> Pc2Writer:
    """A PC2 writer on ``writer_path`` holding the first ``samples`` samples of ``source``,
    ready to append the next."""
    return Pc2Writer.resume(writer_path, source, samples)
