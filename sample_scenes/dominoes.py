"""A domino spiral: thin boxes stand on an Archimedean spiral on the ground; the innermost one is
tipped outward and the fall runs along the spiral to the outermost. Self-check: every domino
has fallen by the end (tilted more than 45 degrees), they fell in order along the spiral,
none sank into the ground, and the last one toppled."""
from __future__ import annotations

import colorsys
import math

import bpy
import numpy as np

from sample_scenes import _common

NAME = "dominoes"
COUNT = 80
SIZE = (0.05, 0.25, 0.5)  # [m] thickness (along the spiral), width, height
SPACING = 0.3  # [m] between neighbours' centres, along the spiral
R_START = 1.0  # [m] radius of the spiral at the first domino
ARM_GAP = 0.55  # [m] between the spiral's turns: more than a fallen domino needs
TIP = 2.5  # [rad/s] the first domino's initial angular velocity, toward the next one
FALLEN_DEG = 45.0  # a domino has fallen once its up axis is tilted this far
TIE_FRAMES = 1  # a domino may pass FALLEN_DEG this many frames before the one before it
SINK = 0.01  # [m] deepest a corner may go below the ground
BANDS = 8  # colours along the spiral

# the first turns of the spiral down (60), the fall running round the outer turns (160), all
# down (270)
SHOWCASE = (60, 160, 270)
README_FRAME = 160


def spiral(count: int) -> tuple[np.ndarray, np.ndarray]:
    """Centres (count, 2) [m] and headings (count,) [rad] of dominoes ``SPACING`` apart along
    the Archimedean spiral r = b theta from radius ``R_START`` outward (counter-clockwise)."""
    b = ARM_GAP / (2.0 * math.pi)
    theta0 = R_START / b
    # r >= R_START all along, so count * SPACING / R_START radians hold the row; twice, to spare
    theta = np.linspace(theta0, theta0 + 2.0 * count * SPACING / R_START, 20000)
    arc = 0.5 * b * (theta * np.sqrt(1.0 + theta ** 2) + np.arcsinh(theta))  # length from 0
    t = np.interp(arc[0] + SPACING * np.arange(count), arc, theta)
    centres = b * t[:, None] * np.stack([np.cos(t), np.sin(t)], axis=1)
    tangent = np.stack([np.cos(t) - t * np.sin(t), np.sin(t) + t * np.cos(t)], axis=1)
    return centres, np.arctan2(tangent[:, 1], tangent[:, 0])


def _names() -> list[str]:
    return [f"Domino{k:03d}" for k in range(COUNT)]


def build(scene) -> None:
    import bmesh
    from mathutils import Matrix

    _common.stage(scene, (0.0, -7.4, 6.8), (0.0, -0.2, 0.0), frame_end=288)
    _common.ground(scene)
    materials = [_common.material(f"Domino{k}", colorsys.hsv_to_rgb(k / BANDS, 0.65, 0.85))
                 for k in range(BANDS)]
    centres, headings = spiral(COUNT)
    for k, name in enumerate(_names()):
        ob = _common.add_mesh(scene, name, lambda bm: bmesh.ops.create_cube(
            bm, size=1.0, matrix=Matrix.Diagonal((*SIZE, 1.0))))
        ob.location = (*centres[k], SIZE[2] / 2)
        ob.rotation_euler = (0.0, 0.0, headings[k])
        ob.data.materials.append(materials[k * BANDS // COUNT])
        ob.physanim.rigid_body.enabled = True
    heading = headings[0]  # the first one turns about the horizontal axis across its path
    axis = np.cross((0.0, 0.0, 1.0), (math.cos(heading), math.sin(heading), 0.0))
    bpy.data.objects[_names()[0]].physanim.rigid_body.initial_angular_velocity = tuple(TIP * axis)


def tilts_and_lows(scene, frames) -> tuple[np.ndarray, np.ndarray]:
    """Each domino's tilt [deg] (its up axis from the vertical) and its lowest corner's height
    [m], (frames, dominoes) each (the dominoes are not scaled: their matrices are rotations)."""
    obs = [bpy.data.objects[n] for n in _names()]
    half = np.array(SIZE) / 2
    tilt, low = [], []
    for f in frames:
        scene.frame_set(f)
        m = np.array([ob.matrix_world for ob in obs])
        tilt.append(np.degrees(np.arccos(np.clip(m[:, 2, 2], -1.0, 1.0))))
        low.append(m[:, 2, 3] - np.abs(m[:, 2, :3]) @ half)
    return np.array(tilt), np.array(low)


def fall_frames(tilt: np.ndarray, frames) -> np.ndarray:
    """The frame each domino first passes FALLEN_DEG (-1: never)."""
    fallen = tilt > FALLEN_DEG
    first = np.asarray(frames)[np.argmax(fallen, axis=0)]
    return np.where(fallen.any(axis=0), first, -1)


def check(scene) -> list[str]:
    problems = []
    frames = list(range(scene.physanim.frame_start, scene.physanim.frame_end + 1))
    names = _names()
    tilt, low = tilts_and_lows(scene, frames)
    standing = [names[k] for k in np.flatnonzero(tilt[-1] <= FALLEN_DEG)]
    if standing:
        problems.append(f"{len(standing)} dominoes still standing at the end: "
                        f"{', '.join(standing[:5])}")
    fell = fall_frames(tilt, frames)
    late = np.flatnonzero((fell[1:] >= 0) & (fell[:-1] >= 0) & (fell[1:] < fell[:-1] - TIE_FRAMES))
    if len(late):
        k = int(late[0])
        problems.append(f"dominoes fell out of order: {names[k + 1]} at frame {fell[k + 1]}, "
                        f"before {names[k]} at frame {fell[k]} ({len(late)} such pairs)")
    deepest = int(np.argmin(low.min(axis=0)))
    if low[:, deepest].min() < -SINK:
        f = frames[int(np.argmin(low[:, deepest]))]
        problems.append(f'"{names[deepest]}" sank {-low[:, deepest].min() * 1000:.0f} mm into the '
                        f"ground at frame {f}")
    if tilt[-1, -1] <= FALLEN_DEG:
        problems.append(f"the last domino did not topple (tilted {tilt[-1, -1]:.0f} degrees)")
    return problems
