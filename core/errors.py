"""Errors raised by the core. Each message names the object, the frame and the value at fault."""
from __future__ import annotations


class PhysanimError(ValueError):
    """Bad input or a simulation failure, with the context a user needs to fix it.

    Args:
        message: what went wrong and, where possible, what to change.
        obj: name of the Blender object (or core entity) at fault, if any.
        frame: scene frame at which it happened, if any.
        kind: what the object is to the simulation ("emitter", "collider", ...).

    The message reads ``emitter "Fountain" at frame 37: particle velocity became NaN — ...``.
    """

    def __init__(
        self,
        message: str,
        *,
        obj: str | None = None,
        frame: int | float | None = None,
        kind: str = "object",
    ):
        self.obj = obj
        self.frame = frame
        self.kind = kind
        self.detail = message
        parts = []
        if obj is not None:
            parts.append(f'{kind} "{obj}"')
        if frame is not None:
            parts.append(f"frame {frame:g}" if isinstance(frame, float) else f"frame {frame}")
        prefix = (" at ".join(parts) + ": ") if parts else ""
        super().__init__(prefix + message)


class SimulationError(PhysanimError):
    """The simulation diverged or produced a non-finite value."""


class at_frame:  # (used as a function: ``with at_frame(frame):``)
    """A PhysanimError raised inside without a frame gains ``frame`` (a class: a generator
    context manager costs three times as much, and this one runs every sub-step)."""

    def __init__(self, frame: int | None):
        self.frame = frame

    def __enter__(self):
        return self

    def __exit__(self, kind, exc, tb) -> bool:
        if isinstance(exc, PhysanimError) and exc.frame is None:
            raise PhysanimError(exc.detail, obj=exc.obj, frame=self.frame,
                                kind=exc.kind) from exc
        return False
