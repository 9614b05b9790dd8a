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

A bake holds such process-wide settings through :class:`Hold` (the others: single-threaded BLAS,
:mod:`.blas`); each is a :class:`Shared`, applied by the first bake and restored by the last.
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


class Shared:
    """A process-wide setting that bakes hold while they run (a UI bake and a script's bake may
    overlap): the first hold applies it, the last one's release restores it. Subclasses say
    whether the setting exists here (:attr:`available`) and how to apply and restore it."""

    def __init__(self):
        self.users = 0  # bakes holding it

    @property
    def available(self) -> bool:
        raise NotImplementedError

    def _apply(self) -> None:
        raise NotImplementedError

    def _restore(self) -> None:
        raise NotImplementedError

    def acquire(self) -> bool:
        """Apply the setting (first user); True when it is in effect."""
        if not self.available:
            return False
        if self.users == 0:
            self._apply()
        self.users += 1
        return True

    def release(self) -> None:
        """Restore the setting (last user)."""
        if not self.available or self.users == 0:
            return
        self.users -= 1
        if self.users == 0:
            self._restore()


class _Glibc(Shared):
    """The process's glibc allocator controls (none where there is no glibc)."""

    def __init__(self):
        super().__init__()
        self.lib = None
        if is_glibc():
            with contextlib.suppress(OSError):
                lib = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
                if hasattr(lib, "mallopt") and hasattr(lib, "malloc_trim"):
                    self.lib = lib

    @property
    def available(self) -> bool:
        return self.lib is not None

    def _apply(self) -> None:
        """The thresholds raised."""
        for param, value in BAKING.items():
            self.lib.mallopt(param, value)

    def _restore(self) -> None:
        """Free memory returned and the thresholds at :data:`AFTER`."""
        for param, value in AFTER.items():
            self.lib.mallopt(param, value)
        self.lib.malloc_trim(0)


GLIBC = _Glibc()


class Hold:
    """One bake's hold on process-wide settings (:class:`Shared`): :meth:`end` (idempotent)
    lets go of them."""

    def __init__(self, *settings: Shared):
        self._held = [s for s in settings if s.acquire()]

    @property
    def active(self) -> bool:
        """Whether any of the settings is in effect."""
        return bool(self._held)

    def end(self) -> None:
        held, self._held = self._held, []
        for setting in held:
            setting.release()


class Reuse(Hold):
    """One bake's hold on the raised thresholds."""

    def __init__(self):
        super().__init__(GLIBC)


@contextlib.contextmanager
def reuse():
    """The raised thresholds for the duration of a ``with`` block."""
    hold = Reuse()
    try:
        yield hold
    finally:
        hold.end()
