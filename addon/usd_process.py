"""USD point layers written by a Python process of their own, on another core than the bake.

Saving a frame's ``.usdc`` layer through ``pxr`` takes about 12 ms per 100,000 points and holds
Python's lock all the while, so on the bake's writer thread it stalls the simulation. A large
emitter's layers are therefore written by a child process instead: the bake's writer thread,
having saved a frame's ``.npz``, hands the child that file's path and the layer's; the child
reads the arrays and saves the layer, the same bits the thread would (:func:`save_usdc` on
:func:`~physanim.core.usd_points.columns`, in both). Where the machine has the cores, several
children take the frames in turn (:class:`UsdPool`): a layer costs more than simulating its
frame's particles, so one child would hold a large bake back. A failure in a child (a full
disk, say) comes back as an :class:`OSError` naming the file, at a later frame or when the
bake finishes.

This file is also the child's script: run by the interpreter Blender runs Python with
(``sys.executable``), it imports only the standard library, numpy, ``core/usd_points.py`` (by
path) and ``pxr`` from the folder it is given. Where no such interpreter can start it (or it
cannot import ``pxr``) the bake writes the layers on its writer thread as before.
"""
from __future__ import annotations

import io
import json
import mmap
import os
import queue
import struct
import subprocess
import sys
import threading
import zipfile
from pathlib import Path

import numpy as np

if __package__:
    from ..core import usd_points
    from ..core.helper_process import cores
    from .allocator import MMAP_MAX
else:  # the child process: this file run as a script
    import importlib.util

    _spec = importlib.util.spec_from_file_location(
        "physanim_usd_points", Path(__file__).resolve().parents[1] / "core" / "usd_points.py")
    usd_points = importlib.util.module_from_spec(_spec)
    _spec.loader.exec_module(usd_points)

#: Frames with fewer points are saved on the writer thread (a few ms at most); an emitter whose
#: frames reach this many has its layers saved by child processes (started with the bake when
#: its estimated peak reaches it, else at its first such frame).
MIN_POINTS = 20_000
#: Seconds the child may take to start and import ``pxr`` before the bake writes without it.
START_TIMEOUT = 30.0
#: Seconds the child may go without saving a layer while the bake waits for its queue (a
#: layer of a million points takes about a fifth of a second): beyond, it is taken for hung,
#: killed, and the bake fails naming it — a farm job ends instead of waiting for ever.
STALL_TIMEOUT = 120.0
#: Children a bake runs for its layers at most (:func:`process_count`), unless the environment
#: variable of that name sets how many.
MAX_PROCESSES = 4
ENVIRONMENT_PROCESSES = "PHYSANIM_USD_PROCESSES"
MAX_ENVIRONMENT_PROCESSES = 32  # (each holds about 340 MB at a million points)


def process_count(emitters: int = 1) -> int:
    """How many children write the layers of each of ``emitters`` large emitters: the cores
    this process may run on (its CPU affinity, as a farm's job slot sets it), up to
    MAX_PROCESSES, shared among the emitters, one each at least. On two cores two: the bake's
    own threads leave a core idle now and then, which the second child takes (a
    100,000-particle bake a quarter faster there; with more cores the layers no longer hold
    the simulation back). The environment variable PHYSANIM_USD_PROCESSES sets the count to
    share instead: 0 (no children: the writer thread writes the layers) up to
    MAX_ENVIRONMENT_PROCESSES.

    Raises:
        ValueError: PHYSANIM_USD_PROCESSES is set to something else.
    """
    raw = os.environ.get(ENVIRONMENT_PROCESSES, "").strip()
    if raw:
        if not (raw.isascii() and raw.isdigit()) or int(raw) > MAX_ENVIRONMENT_PROCESSES:
            raise ValueError(f"{ENVIRONMENT_PROCESSES} must be a whole number of processes from 0 "
                             f"to {MAX_ENVIRONMENT_PROCESSES} (got {raw!r})")
        total = int(raw)
        if total == 0:
            return 0
    else:
        total = min(MAX_PROCESSES, cores())
    return max(1, total // max(1, emitters))


def save_usdc(path: str, data: dict, frame: int, modules: tuple) -> None:
    """The layer :func:`usd_points.points_usda` writes as text, binary through ``pxr``.

    Args:
        path: the ``.usdc`` file (replaced). data: :func:`usd_points.columns` of the frame.
        frame: the layer's time code. modules: ``(Usd, UsdGeom, Vt, Sdf)``.
    """
    Usd, UsdGeom, Vt, Sdf = modules
    if os.path.exists(path):
        os.remove(path)
    stage = Usd.Stage.CreateNew(path)
    stage.SetStartTimeCode(frame)
    stage.SetEndTimeCode(frame)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    prim = UsdGeom.Points.Define(stage, usd_points.PRIM_PATH)
    stage.SetDefaultPrim(prim.GetPrim())
    prim.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(data["points"]))
    if "velocities" in data:
        prim.CreateVelocitiesAttr(Vt.Vec3fArray.FromNumpy(data["velocities"]))
    if "widths" in data:
        prim.CreateWidthsAttr(Vt.FloatArray.FromNumpy(data["widths"]))
    primvars = UsdGeom.PrimvarsAPI(prim)
    for key, column in data.items():
        if key.startswith("primvars:"):
            var = primvars.CreatePrimvar(key.split(":", 1)[1], Sdf.ValueTypeNames.FloatArray,
                                         UsdGeom.Tokens.vertex)
            var.Set(Vt.FloatArray.FromNumpy(column))
    stage.GetRootLayer().Save()


def read_npz(path: str) -> dict[str, np.ndarray]:
    """The arrays of a cache frame as ``np.load`` gives them, but as read-only views of the
    mapped file when its members are stored uncompressed (as ``np.savez`` writes them): no copy
    and no checksum pass over data the bake wrote a moment ago (about 4 ms of the child's
    20 ms per 100,000 points); a member the zip left unaligned is copied. Anything else (a
    compressed member) goes through ``np.load``. The mapping ends when the last array is
    dropped."""
    with open(path, "rb") as handle:
        with zipfile.ZipFile(handle) as archive:
            members = archive.infolist()
        if not members or any(m.compress_type != zipfile.ZIP_STORED or m.flag_bits & 1
                               for m in members):
            with np.load(path, allow_pickle=False) as loaded:
                return {key: loaded[key] for key in loaded.files}
        mapped = mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ)
    arrays = {}
    for member in members:
        try:
            values = _mapped_member(mapped, member)
        except (ValueError, struct.error) as exc:
            raise ValueError(f'"{path}": member {member.filename}: {exc}') from exc
        arrays[member.filename.removesuffix(".npy")] = values
    return arrays


def _mapped_member(mapped: mmap.mmap, member: zipfile.ZipInfo) -> np.ndarray:
    """One stored ``.npy`` member of a mapped zip: a view of it (a copy where unaligned)."""
    # the member's data follow its local header (30 bytes, its name, its extra field)
    signature, = struct.unpack_from("<I", mapped, member.header_offset)
    if signature != 0x04034B50:
        raise ValueError("no local header where the zip's directory puts it")
    name_length, extra_length = struct.unpack_from("<HH", mapped, member.header_offset + 26)
    start = member.header_offset + 30 + name_length + extra_length
    header = io.BytesIO(mapped[start:start + min(member.file_size, 1 << 20)])
    version = np.lib.format.read_magic(header)
    read = (np.lib.format.read_array_header_1_0 if version == (1, 0) else
            np.lib.format.read_array_header_2_0)
    shape, fortran, dtype = read(header)
    if dtype.hasobject:
        raise ValueError("it holds Python objects")
    count = int(np.prod(shape, dtype=np.int64))
    if header.tell() + count * dtype.itemsize != member.file_size or \
            start + member.file_size > len(mapped):
        raise ValueError("its size does not match its array")
    values = np.frombuffer(mapped, dtype, count, start + header.tell())
    if not values.flags.aligned:  # where the zip put it: copied (pxr takes aligned only)
        values = values.copy()
    return values.reshape(shape, order="F" if fortran else "C")


def child_environment() -> dict[str, str]:
    """The child's environment: this one, with (unless set already) ``pxr`` working on one
    thread — its thread pool spun on both cores for about a third more CPU per layer, which
    the bake's simulation on the other core paid for — and glibc's allocator keeping freed
    blocks (as :mod:`.allocator` does for the bake): saving a layer allocates and frees about
    10 MB, which otherwise came back as 2,400 page faults (8 of 19 ms per 100,000 points).
    Other C libraries ignore the ``MALLOC_`` variables."""
    env = dict(os.environ)
    env.setdefault("PXR_WORK_THREAD_LIMIT", "1")
    env.setdefault("MALLOC_MMAP_THRESHOLD_", str(MMAP_MAX))
    env.setdefault("MALLOC_TRIM_THRESHOLD_", str(1 << 30))
    return env


class UsdProcess:
    """The child process, seen from the bake: :meth:`save` queues a layer (on the writer
    thread), :meth:`sync` waits until every queued layer is on disk, :meth:`close` ends it.

    Args:
        site: the folder ``pxr`` imports from in this Blender.
        wait: wait here until the child is ready; else the child starts (imports ``pxr``,
            about 0.3 s) while the bake goes on, and :meth:`wait_ready` must confirm it before
            it is used.

    Raises:
        OSError: the child did not start or could not import ``pxr`` (its reason), here or
            from :meth:`wait_ready`.
    """

    def __init__(self, site: str, wait: bool = True):
        self._replies: queue.Queue[str | None] = queue.Queue()
        self._failure: str | None = None
        self._ready = False
        self._queued = 0  # layers handed to the child and not yet saved
        self._proc = subprocess.Popen(
            [sys.executable, "-s", str(Path(__file__).resolve()), site], stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, encoding="utf-8",
            env=child_environment())
        threading.Thread(target=self._read, name="physanim-usd-replies", daemon=True).start()
        if wait:
            self.wait_ready()

    def wait_ready(self) -> None:
        """Wait until the child has imported ``pxr`` (at most START_TIMEOUT s from here);
        raises OSError with its reason, the child ended, when it cannot."""
        if self._ready:
            return
        try:
            reply = self._replies.get(timeout=START_TIMEOUT)
        except queue.Empty:
            reply = f"no answer in {START_TIMEOUT:g} s"
        if reply != "ready":
            self.close(kill=True)
            raise OSError(f"the USD writer process did not start: {reply or 'it exited'}")
        self._ready = True

    def _read(self) -> None:
        for line in self._proc.stdout:
            self._replies.put(line.rstrip("\n"))
        self._replies.put(None)  # the child exited

    def _raise_failure(self) -> None:
        if self._failure is None:
            while True:
                try:
                    reply = self._replies.get_nowait()
                except queue.Empty:
                    return
                if reply == "saved":
                    self._queued -= 1
                elif reply != "ok":
                    self._failure = reply or "the USD writer process exited"
                    break
        raise OSError(self._failure.removeprefix("error: "))

    def save(self, path: Path, data: tuple) -> None:
        """Queue the layer ``path`` of the frame whose ``.npz`` is written: ``data`` is
        ``(npz path, frame)``. Raises the child's failure of an earlier layer."""
        self._raise_failure()
        npz, frame = data
        try:
            self._proc.stdin.write(json.dumps([int(frame), str(npz), str(path)]) + "\n")
            self._proc.stdin.flush()
            self._queued += 1
        except OSError:
            self._replies.put(None)
            self._raise_failure()

    def sync(self) -> None:
        """Wait until every queued layer is saved; raises the first failure, or an OSError
        (the child killed) when it saves none for STALL_TIMEOUT seconds."""
        self._raise_failure()
        try:
            self._proc.stdin.write("sync\n")
            self._proc.stdin.flush()
        except OSError:
            self._replies.put(None)
        while (reply := self._reply()) == "saved":
            self._queued -= 1
        if reply != "ok":
            self._failure = reply or "the USD writer process exited"
            self._raise_failure()

    def _reply(self) -> str | None:
        """The child's next answer, waiting at most STALL_TIMEOUT seconds for it (else the
        child is killed and the wait fails)."""
        try:
            return self._replies.get(timeout=STALL_TIMEOUT)
        except queue.Empty:
            self._proc.kill()
            try:
                self._proc.wait(timeout=10)  # (gone: its exit collected)
            except subprocess.TimeoutExpired:
                pass
            self._failure = (f"the USD writer process saved no layer in {STALL_TIMEOUT:g} s "
                             f"({self._queued} waiting) and was stopped")
            self._raise_failure()

    def close(self, kill: bool = False) -> None:
        """End the child: ``kill`` at once (the layers are thrown away), else once its queue is
        written."""
        proc = self._proc
        if proc.poll() is None:
            if kill:
                proc.kill()
            else:
                try:
                    proc.stdin.close()
                except OSError:
                    proc.kill()
        try:
            if not kill and self._failure is None:  # it saves what is queued, then exits
                while self._reply() is not None:
                    pass
            proc.wait(timeout=10)
        finally:
            for pipe in (proc.stdin, proc.stdout):
                try:
                    pipe.close()
                except OSError:
                    pass


class UsdPool:
    """``count`` children (:class:`UsdProcess`) seen as one: :meth:`save` hands each layer
    to the next in turn; :meth:`sync` waits for all of them; :meth:`close` ends all of them.

    Args:
        site, wait: as for :class:`UsdProcess` (all start at once; ``wait`` then waits for
            each). count: the children (>= 1).

    Raises:
        OSError: a child did not start (here or from :meth:`wait_ready`); the others are
            ended with it (as on any exception while they start).
    """

    def __init__(self, site: str, count: int, wait: bool = True):
        self.processes: list[UsdProcess] = []
        self._next = 0
        try:
            for _ in range(max(1, int(count))):
                self.processes.append(UsdProcess(site, wait=False))
            if wait:
                self.wait_ready()
        except BaseException:
            self.close(kill=True)
            raise

    def wait_ready(self) -> None:
        try:
            for process in self.processes:
                process.wait_ready()
        except BaseException:
            self.close(kill=True)
            raise

    def save(self, path: Path, data: tuple) -> None:
        """As :meth:`UsdProcess.save`, by the next child in turn."""
        process = self.processes[self._next % len(self.processes)]
        self._next += 1
        process.save(path, data)

    def sync(self) -> None:
        for process in self.processes:
            process.sync()

    def close(self, kill: bool = False) -> None:
        close_all(self.processes, kill)


def close_all(processes, kill: bool = False) -> None:
    """``close(kill)`` every one of ``processes`` (children or pools), each even when another
    fails to end; raises the first failure."""
    failure = None
    for process in processes:
        try:
            process.close(kill)
        except BaseException as exc:
            failure = failure or exc
    if failure is not None:
        raise failure


def _save_layer(frame: int, npz: str, path: str, modules: tuple) -> None:
    """One layer from one cache frame; the frame's mapping ends on return (nothing here keeps
    its arrays), before the bake may move the folder."""
    save_usdc(path, usd_points.columns(read_npz(npz)), frame, modules)


def _serve(site: str) -> int:
    """The child: a line per layer (``[frame, npz, usdc]`` in JSON) or ``sync``; answers
    ``ready`` once ``pxr`` imports, ``saved`` per layer, ``ok`` per ``sync``, ``error: ...``
    and exits on a failure."""
    try:
        sys.path.append(site)
        from pxr import Sdf, Usd, UsdGeom, Vt
    except Exception as exc:  # any reason it cannot write is the answer
        print(f"error: cannot import pxr from {site}: {exc}", flush=True)
        return 1
    modules = (Usd, UsdGeom, Vt, Sdf)
    print("ready", flush=True)
    for line in sys.stdin:
        if line.strip() == "sync":
            print("ok", flush=True)
            continue
        frame, npz, path = json.loads(line)
        try:
            _save_layer(frame, npz, path, modules)
        except Exception as exc:  # reported to the bake, which names the file
            print(f'error: USD points file "{path}" (frame {frame}) was not written: {exc}',
                  flush=True)
            return 1
        print("saved", flush=True)  # (the bake knows it is still working)
    return 0


if __name__ == "__main__":
    sys.exit(_serve(sys.argv[1]))
