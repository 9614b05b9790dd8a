"""The scene's Time Scale as a :class:`~..core.controls.timing.TimeMap`: simulated time per
frame, read at every frame of the bake when it is animated (keys or a driver)."""
from __future__ import annotations

import numpy as np

from ..core.controls.timing import MAX_SCALE, MIN_SCALE, TimeMap
from ..core.errors import PhysanimError
from . import compat, convert

DATA_PATH = "physanim.time_scale"


def animated(scene) -> bool:
    """Whether the scene's Time Scale has keys or a driver."""
    anim = scene.animation_data
    if anim is None:
        return False
    return any(fc.data_path == DATA_PATH for fc in (*compat.action_fcurves(anim), *anim.drivers))


def time_map(scene, frame_start: int, frame_end: int) -> TimeMap:
    """The time map of a bake over ``frame_start`` .. ``frame_end``; an error naming the
    scene and the frame when a scale is out of range. Leaves the scene's frame as it was."""
    if animated(scene):
        current = (scene.frame_current, scene.frame_subframe)
        scale = np.empty(frame_end - frame_start + 1)
        try:
            for k in range(len(scale)):
                scene.frame_set(frame_start + k)
                scale[k] = scene.physanim.time_scale  # the property clamps keys to its range
        finally:
            scene.frame_set(current[0], subframe=current[1])
    else:
        scale = np.full(max(1, frame_end - frame_start + 1), scene.physanim.time_scale)
    # Blender keeps the property in single precision: its own limits read back a rounding
    # beyond them (0.01 as 0.0099999998) and are the limits
    for limit in (MIN_SCALE, MAX_SCALE):
        scale[scale == float(np.float32(limit))] = limit
    try:
        return TimeMap(frame_start, scale)
    except ValueError as exc:
        raise PhysanimError(str(exc), obj=scene.name, kind="scene") from exc


def go_to(scene, frame: float) -> None:
    """Set the scene to a (float) frame: a whole frame, or a frame and sub-frame."""
    whole = int(np.floor(frame))
    scene.frame_set(whole, subframe=float(frame - whole))


def frame_seconds(clock: TimeMap, scene, frames) -> np.ndarray:
    """Simulated time [s] of (float) frames under ``clock``."""
    return clock.seconds(frames, convert.seconds_per_frame(scene))
