"""The one place where Blender's units meet the core's: frames <-> seconds, axes, matrices."""
from __future__ import annotations

import numpy as np

AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0),
        "-X": (-1.0, 0.0, 0.0), "-Y": (0.0, -1.0, 0.0), "-Z": (0.0, 0.0, -1.0)}


def fps(scene) -> float:
    """Frames per second of a scene (fps / fps_base)."""
    return scene.render.fps / scene.render.fps_base


def seconds_per_frame(scene) -> float:
    """Length of one frame [s]."""
    return 1.0 / fps(scene)


def frames_to_seconds(scene, frames):
    """A duration or frame number (float or numpy array) in seconds; the core's clock starts at
    frame 0."""
    return frames * seconds_per_frame(scene)


def frame_time(scene, frame: float) -> float:
    """Time [s] of a frame."""
    return frames_to_seconds(scene, frame)


def seconds_to_frames(scene, seconds):
    """A duration or time [s] (float or numpy array) in frames."""
    return seconds * fps(scene)


def matrix(m) -> np.ndarray:
    """A mathutils 4x4 Matrix as a numpy (4, 4) float64 array (row-major, column vectors)."""
    return np.array([tuple(row) for row in m], dtype=np.float64)


def gravity(scene) -> tuple[float, float, float]:
    """Scene gravity [m/s^2] (Blender is Z-up; zero when the scene disables gravity)."""
    if not scene.use_gravity:
        return (0.0, 0.0, 0.0)
    return tuple(float(g) for g in scene.gravity)
