"""On-disk bake cache: one folder per bake, one sub-folder per stream, one ``.npz`` per frame.

Layout::

    <cache_dir>/
        meta.json                 inputs hash, frame range, per-stream info (written last)
        <stream>/frame_000001.npz arrays of one frame (uncompressed: fast to read while scrubbing)

A bake streams frames into a fresh sibling folder and swaps it in only on success
(:meth:`CacheWriter.commit`); :meth:`CacheWriter.abort` — on error or cancel — deletes the partial
folder, so the previous bake stays exactly as it was. Memory does not grow with the frame count.
"""
from __future__ import annotations

import json
import os
import shutil
import uuid
import zipfile
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

META_NAME = "meta.json"
FORMAT_VERSION = 1
WRITES_IN_FLIGHT = 2  # frames queued for the writer thread; bounds the memory a bake holds


def frame_file(stream_dir: str | os.PathLike, frame: int) -> Path:
    """Path of one frame's arrays inside a stream folder."""
    return Path(stream_dir) / f"frame_{int(frame):06d}.npz"


def read_frame(stream_dir: str | os.PathLike, frame: int) -> dict[str, np.ndarray] | None:
    """Arrays of ``frame`` in ``stream_dir``, or None when that frame was not baked."""
    path = frame_file(stream_dir, frame)
    if not path.is_file():
        return None
    with np.load(path, allow_pickle=False) as data:
        return {key: data[key] for key in data.files}


def read_meta(cache_dir: str | os.PathLike) -> dict | None:
    """The ``meta.json`` of a finished bake, or None when there is no finished bake there."""
    path = Path(cache_dir) / META_NAME
    if not path.is_file():
        return None
    with open(path, encoding="utf-8") as handle:
        return json.load(handle)


class CacheWriter:
    """Writes a bake into a temporary folder and swaps it in atomically on :meth:`commit`.

    Args:
        cache_dir: final folder of the bake. Its parent is created when missing; it must be
            writable, otherwise :class:`PermissionError`/:class:`OSError` names the folder.
    """

    def __init__(self, cache_dir: str | os.PathLike, background: bool = True):
        self.cache_dir = Path(cache_dir)
        parent = self.cache_dir.parent
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OSError(f'cache folder "{parent}" cannot be created: {exc.strerror}') from exc
        if not os.access(parent, os.W_OK | os.X_OK):
            raise PermissionError(f'cache folder "{parent}" is not writable')
        token = uuid.uuid4().hex[:8]
        self.partial_dir = parent / f".{self.cache_dir.name}.partial-{token}"
        try:
            self.partial_dir.mkdir()
        except OSError as exc:
            raise OSError(f'cache folder "{parent}" is not writable: {exc.strerror}') from exc
        self._streams: set[str] = set()
        self._closed = False
        # Files are written by one background thread (file I/O releases the GIL), so the next
        # frame simulates while this one goes to disk; at most WRITES_IN_FLIGHT frames wait.
        self._pool = ThreadPoolExecutor(1, "physanim-cache") if background else None
        self._pending: list[Future] = []
        self._helpers: list = []

    def attach(self, helper) -> None:
        """Make ``helper`` part of this bake's writing: something that writes files of the
        partial folder elsewhere (a process of its own, say), with ``sync()`` (wait until they
        are written; raise their first error) and ``close(kill)``. :meth:`flush` syncs it after
        the queued writes; commit, detach and abort close it (abort kills it)."""
        if self._closed:
            raise RuntimeError("cache writer already committed or aborted")
        self._helpers.append(helper)

    def write_frame(self, stream: str, frame: int, arrays: Mapping[str, np.ndarray]) -> Path:
        """Write one frame of one stream (e.g. one emitter's particles).

        The arrays must not be modified afterwards (they may still be queued for writing).
        Errors of earlier queued writes are raised here or by :meth:`commit`.
        """
        data = {k: np.ascontiguousarray(v) for k, v in arrays.items()}
        return self.write_file(stream, frame_file(".", frame).name, _save, data)

    def write_file(self, stream: str, name: str, save: Callable[[Path, Any], None],
                   data: Any) -> Path:
        """Queue ``save(path, data)`` for the file ``name`` of ``stream`` (one frame of an
        export format, say) on the writer thread; returns the path it is written to."""
        if self._closed:
            raise RuntimeError("cache writer already committed or aborted")
        stream_dir = self.partial_dir / stream
        if stream not in self._streams:
            stream_dir.mkdir(parents=True, exist_ok=True)
            self._streams.add(stream)
        path = stream_dir / name
        if self._pool is None:
            save(path, data)
            return path
        while len(self._pending) >= WRITES_IN_FLIGHT:
            self._pending.pop(0).result()
        self._pending.append(self._pool.submit(save, path, data))
        return path

    def flush(self) -> None:
        """Wait for queued writes; raises the first write error."""
        while self._pending:
            self._pending.pop(0).result()
        for helper in self._helpers:
            helper.sync()

    def _shutdown(self, kill: bool = False) -> None:
        if self._pool is not None:
            for future in self._pending:
                future.cancel()
            self._pool.shutdown(wait=True)
            self._pool = None
        self._pending.clear()
        helpers, self._helpers = self._helpers, []
        for helper in helpers:
            helper.close(kill)

    def file_path(self, name: str) -> Path:
        """A file of the bake (e.g. a PC2 mesh cache) to write now: it is created inside the
        partial folder and appears at ``cache_dir / name`` once committed."""
        if self._closed:
            raise RuntimeError("cache writer already committed or aborted")
        return self.partial_dir / name

    def commit(self, meta: Mapping) -> Path:
        """Write ``meta.json`` and replace the previous bake (if any) with this one."""
        if self._closed:
            raise RuntimeError("cache writer already committed or aborted")
        try:
            self.flush()
        finally:
            self._shutdown()
        meta = dict(meta, format_version=FORMAT_VERSION, streams=sorted(self._streams))
        with open(self.partial_dir / META_NAME, "w", encoding="utf-8") as handle:
            json.dump(meta, handle, indent=1, sort_keys=True)
        old = None
        if self.cache_dir.exists():
            old = self.cache_dir.parent / f".{self.cache_dir.name}.old-{uuid.uuid4().hex[:8]}"
            os.replace(self.cache_dir, old)
        os.replace(self.partial_dir, self.cache_dir)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        self._closed = True
        return self.cache_dir

    def detach(self) -> Path:
        """Stop writing and keep the partial folder as it is (every queued frame written), for
        a later resume; returns it. The previous bake (if any) is untouched."""
        if not self._closed:
            try:
                self.flush()
            finally:
                self._shutdown()
                self._closed = True
        return self.partial_dir

    def abort(self) -> None:
        """Delete the partial bake; the previous bake (if any) is untouched."""
        if not self._closed:
            self._shutdown(kill=True)
            shutil.rmtree(self.partial_dir, ignore_errors=True)
            self._closed = True


def _save(path: Path, arrays: Mapping[str, np.ndarray]) -> None:
    """``np.savez`` of ``arrays``, the same zip members, without its copy of each array: the
    members are written from the arrays' own memory (a fifth of a 100,000-particle frame's
    writing time went to those copies). Object arrays are refused (``np.savez`` would pickle
    them; frames are read without pickles)."""
    with open(path, "wb") as handle, \
            zipfile.ZipFile(handle, "w", zipfile.ZIP_STORED, allowZip64=True) as archive:
        for key, values in arrays.items():
            with archive.open(f"{key}.npy", "w", force_zip64=True) as member:
                if values.flags.c_contiguous and values.size and values.dtype.names is None \
                        and not values.dtype.hasobject:
                    header = np.lib.format.header_data_from_array_1_0(values)
                    np.lib.format.write_array_header_1_0(member, header)
                    member.write(memoryview(values.reshape(-1).view(np.uint8)))
                else:  # F-ordered, empty or structured arrays: numpy's own way
                    np.lib.format.write_array(member, values, allow_pickle=False)


def remove_cache(cache_dir: str | os.PathLike) -> bool:
    """Delete a finished bake folder. Returns True when there was one."""
    path = Path(cache_dir)
    if (path / META_NAME).is_file():
        shutil.rmtree(path)
        return True
    return False
