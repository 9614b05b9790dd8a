"""numpy's BLAS on one thread while a bake runs (OpenBLAS, as the numpy wheels ship it).

The solvers call BLAS and LAPACK on small matrices (a multigrid's coarsest level, a chain's
joint blocks, a constraint system). OpenBLAS splits such calls over a pool of threads, one per
core, that spin while they wait for work. On an idle machine that gains little; when anything
else keeps a core busy — Blender drawing or rendering, a second bake, another job on a farm
node, a test runner's other worker — each split call waits for a thread that is not running:
measured here (2 cores, one busy with another process) a 30 x 30 inverse took 34 ms instead of
0.05 ms, and a self-colliding cloth's bake 16.5 s instead of 11.5 s. A single thread also
makes a bake's arithmetic independent of the machine's core count (a split sum adds in another
order). So while any bake runs, OpenBLAS runs on the calling thread; the count it had is given
back when the last bake ends.

Found among the libraries the process has loaded (``/proc/self/maps`` on Linux) or, elsewhere,
beside numpy (its wheels' ``numpy.libs``, ``numpy/.libs``, ``numpy/.dylibs``). A numpy built on
another BLAS (Accelerate, MKL, its own lapack_lite) is left alone: nothing here changes it.
"""
from __future__ import annotations

import contextlib
import ctypes
import os
from pathlib import Path

from .allocator import Hold, Shared

# the symbols' prefixes and suffixes in the builds numpy ships (64-bit integer builds add a
# suffix; the scipy-openblas builds of numpy 2 add a prefix)
_PREFIXES = ("", "scipy_")
_SUFFIXES = ("", "64_", "_64")


class _Library:
    """One loaded OpenBLAS: its thread count, read and set."""

    def __init__(self, path: str, get, set_):
        self.path, self._get, self._set = path, get, set_
        self._get.restype, self._get.argtypes = ctypes.c_int, []
        self._set.restype, self._set.argtypes = None, [ctypes.c_int]

    def threads(self) -> int:
        return int(self._get())

    def set_threads(self, count: int) -> None:
        self._set(int(count))


def _loaded_paths() -> list[str]:
    """Paths of the OpenBLAS libraries this process has mapped (Linux), else those beside
    numpy."""
    paths: list[str] = []
    with contextlib.suppress(OSError):
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as maps:
            for line in maps:
                path = line.rstrip("\n").split(maxsplit=5)[-1]
                if path.startswith("/") and "openblas" in os.path.basename(path).lower() \
                        and path not in paths:
                    paths.append(path)
    if paths:
        return paths
    try:
        import numpy

        root = Path(numpy.__file__).resolve().parent
    except (ImportError, AttributeError, TypeError):
        return []
    for folder in (root.parent / "numpy.libs", root / ".libs", root / ".dylibs"):
        if folder.is_dir():
            paths += sorted(str(p) for p in folder.iterdir() if "openblas" in p.name.lower())
    return paths


def _open(path: str) -> _Library | None:
    """The library at ``path`` if it is loaded already and has the thread-count calls."""
    mode = getattr(os, "RTLD_NOLOAD", 0) | getattr(os, "RTLD_LAZY", 0)  # never load another
    try:
        lib = ctypes.CDLL(path, mode=mode) if mode else ctypes.CDLL(path)
    except OSError:
        return None
    for prefix in _PREFIXES:
        for suffix in _SUFFIXES:
            get = getattr(lib, f"{prefix}openblas_get_num_threads{suffix}", None)
            set_ = getattr(lib, f"{prefix}openblas_set_num_threads{suffix}", None)
            if get is not None and set_ is not None:
                return _Library(path, get, set_)
    return None


class _OpenBLAS(Shared):
    """Every loaded OpenBLAS on one thread while held (found on first use)."""

    def __init__(self):
        super().__init__()
        self._libraries: list[_Library] | None = None
        self._saved: list[int] = []

    @property
    def libraries(self) -> list[_Library]:
        if self._libraries is None:
            self._libraries = [lib for lib in map(_open, _loaded_paths()) if lib is not None]
        return self._libraries

    @property
    def available(self) -> bool:
        return bool(self.libraries)

    def threads(self) -> list[int]:
        """Each library's thread count now."""
        return [lib.threads() for lib in self.libraries]

    def _apply(self) -> None:
        self._saved = self.threads()
        for lib in self.libraries:
            lib.set_threads(1)

    def _restore(self) -> None:
        for lib, count in zip(self.libraries, self._saved):
            lib.set_threads(count)


OPENBLAS = _OpenBLAS()


class OneThread(Hold):
    """One bake's hold on single-threaded BLAS."""

    def __init__(self):
        super().__init__(OPENBLAS)
