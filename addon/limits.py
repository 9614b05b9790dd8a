"""Hard limits on the inputs Blender owns (gravity, frame rate, object scales, the bake's
length), checked before a bake starts, and the scene's bounds on the simulated state.

Our own properties carry their limits in their definitions (``min``/``max``); Blender's have
none of ours, so an absurd value there (gravity -1e35) must fail here with a message naming the
scene or object and the value, before anything is written.
"""
from __future__ import annotations

import math

import numpy as np

from ..core.bounds import StateBounds
from ..core.errors import PhysanimError
from . import convert

MAX_GRAVITY = 1.0e3  # [m/s^2]: about 100 g
FPS_RANGE = (0.1, 1.0e4)  # [frames/s]
MAX_SCALE = 1.0e6  # largest scale of a role object's world matrix
MAX_BAKE_FRAMES = 100_000  # a bake's length (over an hour at 24 fps)


def bounds(scene) -> StateBounds:
    """The scene's bounds on the simulated state (Scene > PhysAnim > Limits)."""
    s = scene.physanim
    return StateBounds(position=s.world_bound, speed=s.speed_limit)


def check_scene(scene, frame_start: int, frame_end: int) -> None:
    """Gravity, frame rate and bake length within their hard limits, or an error naming the
    scene, the frame and the value."""
    def fail(msg: str):
        raise PhysanimError(msg, obj=scene.name, frame=frame_start, kind="scene")

    g = convert.gravity(scene)
    size = math.sqrt(sum(c * c for c in g)) if all(math.isfinite(c) for c in g) else math.inf
    if size > MAX_GRAVITY:
        shown = ", ".join(f"{c:.4g}" for c in g)
        fail(f"gravity ({shown}) m/s² is beyond the limit of "
             f"{MAX_GRAVITY:g} m/s² — check Scene > Gravity")
    fps = convert.fps(scene)
    if not (math.isfinite(fps) and FPS_RANGE[0] <= fps <= FPS_RANGE[1]):
        fail(f"the frame rate {fps:.6g} fps (fps {scene.render.fps} / base "
             f"{scene.render.fps_base:g}) is outside {FPS_RANGE[0]:g}-{FPS_RANGE[1]:g} fps — "
             "check Output > Frame Rate")
    length = frame_end - frame_start + 1
    if length > MAX_BAKE_FRAMES:
        fail(f"the bake spans {length:,} frames ({frame_start}-{frame_end}); the limit is "
             f"{MAX_BAKE_FRAMES:,} — bake the shot in parts")


def check_scale(ob, m: np.ndarray, frame: float, kind: str) -> None:
    """A role object's world scale within :data:`MAX_SCALE` (its matrix is already finite)."""
    scale = np.linalg.norm(m[:3, :3], axis=0)
    if (scale > MAX_SCALE).any():
        shown = ", ".join(f"{s:.4g}" for s in scale)
        raise PhysanimError(f"its world scale ({shown}) is beyond "
                            f"the limit of {MAX_SCALE:g} — check its scale, animation and "
                            "parents", obj=ob.name, frame=frame, kind=kind)
