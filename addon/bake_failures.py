"""The failure side of a bake (:class:`Failures`, mixed into :class:`.bake.BakeJob`): a system
whose add-on work or simulation fails is dropped — its partial cache deleted, its previous bake
kept (a spring mesh's cache modifier, rigid bodies' earlier keys) — and the others go on; only
when none is left does the failure stop the bake. The report names each that failed."""
from __future__ import annotations

import contextlib

import bpy

from ..core.errors import PhysanimError
from . import rigid_keys, springs


class Failures:
    """Failures of a :class:`.bake.BakeJob` (which holds the systems and the fields used
    here)."""

    @contextlib.contextmanager
    def _system(self, channel):
        """Run one system's add-on work (reading its inputs, writing its frames)."""
        try:
            yield
        except (PhysanimError, ValueError) as exc:
            self._drop(channel, exc)

    def _drop(self, channel, exc: Exception) -> None:
        """A system failed: delete its partial cache, keep its previous bake, and go on with
        the others; re-raise when none is left."""
        if channel is not self.particles and channel is not self.rigid \
                and channel not in self.meshes:
            return  # dropped already (a failure inside its own guarded work)
        channel.abort()
        self.world.drop(channel.system)
        if channel is self.particles:
            self.particles = None
            self._failed(channel.label, None, exc)
        elif channel is self.rigid:
            self.rigid = None
            self._restore_rigid()
            self._failed(channel.label, None, exc)
        else:
            self.meshes.remove(channel)
            self._failed(channel.label, channel.ob.name, exc)

    def _failed(self, label: str, mesh: str | None, exc: Exception) -> None:
        if mesh is not None:
            springs.restore_modifier(bpy.data.objects[mesh], self.suspended.pop(mesh, None))
        self.failures.append((label, str(exc)))
        if self.particles is None and self.rigid is None and not self.meshes \
                and not self._unprepared:
            raise exc

    def _restore_rigid(self) -> None:
        """Earlier rigid-body keys back on their objects (the new bake did not finish)."""
        for name, baked in self.rigid_suspended.items():
            rigid_keys.restore(bpy.data.objects[name], baked)
        self.rigid_suspended.clear()

    def _emitter_read(self, read) -> list:
        """``read()`` of emitter values: a failure there is the particle system's; [] once the
        particle system has failed (or when there is none)."""
        if self.particles is not None:
            with self._system(self.particles):
                return read()
        return []

    def _channel(self, system):
        if self.particles is not None and system is self.particles.system:
            return self.particles
        if self.rigid is not None and system is self.rigid.system:
            return self.rigid
        return next(mesh for mesh in self.meshes if mesh.system is system)

    def failure_report(self, info: str) -> str | None:
        """One message naming every system that failed (each keeps its previous bake) and what
        did bake; None when nothing failed."""
        if not self.failures:
            return None
        failed = "; ".join(message for _, message in self.failures)
        names = ", ".join(what for what, _ in self.failures)
        return (f"{failed} — not baked (previous bake kept): {names}; the rest baked "
                f"({info.removeprefix('baked ')})")
