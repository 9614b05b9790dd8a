"""Memory reuse during a bake (Linux, glibc): numpy's state-sized temporaries are reused instead
of being handed back to the system and faulted in again every sub-step.

A bake's passes allocate many arrays of the state's size (100,000 particles: 2.4 MB each) and free
them within the sub-step. glibc gives memory above its trim threshold back to the system on each
free and maps large blocks afresh, so every such array costs page faults on first touch: on the
project machine about 1 ms per 2.4 MB array, more than the arithmetic done on it (a 100,000-
particle bake spent a third of its time there). While any bake runs, :func:`reuse` raises the
thresholds so freed blocks stay in the heap for the next sub-step; when the last bake ends, the
free memory is returned (``malloc_trim``) and the thresholds are left where glibc's own dynamic
mode settles once a large block has been freed (any ``mallopt`` of them ends that mode for the
process, so it cannot be switched back on): blocks up to 32 MiB from the heap, up to twice that
kept free at its top.

Elsewhere (macOS, Windows, musl) this does nothing: their allocators keep memory differently.
"""
from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import platform

# mallopt(3) parameters
M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_THRESHOLD = -1, -2, -3
MMAP_MAX = 32 * 1024 * 1024  # [bytes] the largest mmap threshold glibc allows (64-bit): a
# 1,000,000-particle (n, 3) array is 24 MB
# while baking: every block up to MMAP_MAX comes from the heap; up to 1 GiB of free heap is kept
BAKING = {M_MMAP_THRESHOLD: MMAP_MAX, M_TRIM_THRESHOLD: 1 << 30, M_TOP_PAD: 64 * 1024 * 1024}
# after: glibc's dynamic mode's settled state (threshold at the largest freed block, trim at
# twice it) and its default top pad (128 KiB, mallopt(3))
AFTER = {M_MMAP_THRESHOLD: MMAP_MAX, M_TRIM_THRESHOLD: 2 * MMAP_MAX, M_TOP_PAD: 128 * 1024}


def is_glibc() -> bool:
    """Whether this process runs on glibc (asked of the C library itself: instant, where
    ``platform.libc_ver`` would scan the Blender executable)."""
    if platform.system() != "Linux":
        return False
    try:
        return os.confstr("CS_GNU_LIBC_VERSION").startswith("glibc")
    except (ValueError, OSError, AttributeError):
        return False


class _Glibc:
    """The process's glibc allocator controls, or None where there is no glibc."""

    def __init__(self):
        self.lib = None
        self.users = 0  # bakes running (a UI bake and a script's bake may overlap)
        if is_glibc():
            with contextlib.suppress(OSError):
                lib = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
                if hasattr(lib, "mallopt") and hasattr(lib, "malloc_trim"):
                    self.lib = lib

    def acquire(self) -> bool:
        """Raise the thresholds (first user); True when they are in effect."""
        if self.lib is None:
            return False
        if self.users == 0:
            for param, value in BAKING.items():
                self.lib.mallopt(param, value)
        self.users += 1
        return True

    def release(self) -> None:
        """Free memory returned and the thresholds at :data:`AFTER` (last user)."""
        if self.lib is None or self.users == 0:
            return
        self.users -= 1
        if self.users == 0:
            for param, value in AFTER.items():
                self.lib.mallopt(param, value)
            self.lib.malloc_trim(0)


_GLIBC = _Glibc()


class Reuse:
    """One bake's hold on the raised thresholds: :meth:`end` (idempotent) lets it go."""

    def __init__(self):
        self._held = _GLIBC.acquire()

    @property
    def active(self) -> bool:
        return self._held

    def end(self) -> None:
        if self._held:
            self._held = False
            _GLIBC.release()


@contextlib.contextmanager
def reuse():
    """The raised thresholds for the duration of a ``with`` block."""
    hold = Reuse()
    try:
        yield hold
    finally:
        hold.end()
