"""A robot arm throws a crate at a pyramid of boxes: the crate is a rigid body held in the arm's
gripper (it is parented to the forearm and its Animated switch is keyed on), and the switch is
keyed off at the release frame: from there the crate is simulated, leaving with the velocity
the arm's motion gave it. It flies about six metres and knocks the pyramid over.

Every rigid-body setting is the default but the keyed switch and the crate's mass. Self-check: while held, the
crate is exactly where the gripper holds it; it leaves with the gripper's velocity at the
release (within 5 %); it reaches the pyramid and knocks most of its boxes off their places;
nothing sinks into the ground; everything is at rest at the end.
"""
from __future__ import annotations

import math

import bpy
import numpy as np

from sample_scenes import _common

NAME = "arm_throw"
SEGMENTS = (("Base", 0.6), ("UpperArm", 1.6), ("Forearm", 1.2))
CRATE = 0.35  # [m] the crate's edge
CRATE_MASS = 8.0  # [kg] a heavy crate (the boxes: the default 1 kg)
GRIP = 0.25  # [m] the crate's centre beyond the forearm's end, along it
RELEASE = 37  # the last frame the crate is held: simulated from here on
BOX = 0.4  # [m] the pyramid's boxes
ROWS = 4  # the pyramid's rows (4 + 3 + 2 + 1 boxes)
PYRAMID_X = 4.0  # [m] the pyramid's centre along the throw
FRAMES = 120
RELEASE_TOLERANCE = 0.05  # the crate's speed after the release vs the gripper's, relative
KNOCKED = 0.2  # [m] a pyramid box counts as knocked over once moved this far ...
KNOCKED_DEG = 20.0  # ... or tilted this much
KNOCKED_SHARE = 0.5  # at least this share of the pyramid
SINK = 0.01  # [m] deepest a corner may go below the ground
AT_REST = 0.05  # [m/s] fastest any body may move at the end

# the swing with the crate in hand (30), the crate in flight (52), the impact (66), the pyramid
# scattered (110)
SHOWCASE = (30, 52, 66, 110)
README_FRAME = 66


def _deg(values) -> list[tuple[int, float]]:
    return [(frame, math.radians(angle)) for frame, angle in values]


def pyramid() -> list[tuple[str, tuple[float, float, float]]]:
    """(name, centre) of every box of the pyramid, bottom row first."""
    boxes = []
    for row in range(ROWS):
        count = ROWS - row
        for k in range(count):
            x = PYRAMID_X + (k - (count - 1) / 2) * BOX * 1.02
            boxes.append((f"Box{row}{k}", (x, 0.0, BOX / 2 + row * BOX)))
    return boxes


def build(scene) -> None:
    import bmesh

    _common.stage(scene, (2.4, -13.0, 3.0), (2.4, 0.0, 1.8), frame_end=FRAMES)
    _common.ground(scene)
    joints = _common.robot_arm(scene, SEGMENTS)
    _base, upper, fore = joints
    # wind up slowly (frames 1-20), swing forward (20-50), the crate let go mid-swing
    _common.key_values(upper, "rotation_euler", 1,
                       _deg([(1, -15), (20, -80), (60, 30), (80, 20)]))
    _common.key_values(fore, "rotation_euler", 1, _deg([(1, 20), (20, -30), (60, 20), (80, 15)]))

    crate = _common.add_mesh(scene, "Crate", lambda bm: bmesh.ops.create_cube(bm, size=CRATE))
    crate.data.materials.append(_common.material("Crate", (0.2, 0.55, 0.9)))
    crate.parent = fore
    crate.location = (0.0, 0.0, SEGMENTS[-1][1] + GRIP)
    body = crate.physanim.rigid_body
    body.enabled = True
    body.mass = CRATE_MASS
    for frame, held in ((1, True), (RELEASE + 1, False)):
        body.kinematic = held
        crate.keyframe_insert("physanim.rigid_body.kinematic", frame=frame)

    colours = [_common.material(f"Pyramid{r}", c) for r, c in enumerate(
        ((0.85, 0.25, 0.2), (0.9, 0.7, 0.2), (0.3, 0.75, 0.35), (0.6, 0.35, 0.8)))]
    for name, centre in pyramid():
        ob = _common.add_mesh(scene, name, lambda bm: bmesh.ops.create_cube(bm, size=BOX))
        ob.location = centre
        ob.data.materials.append(colours[int(name[3])])
        ob.physanim.rigid_body.enabled = True


def gripper(scene, frame: float) -> np.ndarray:
    """Where the gripper holds the crate's centre at ``frame`` (world, [m])."""
    scene.frame_set(int(math.floor(frame)), subframe=frame - math.floor(frame))
    from mathutils import Vector

    fore = bpy.data.objects["Forearm"]
    return np.array(fore.matrix_world @ Vector((0.0, 0.0, SEGMENTS[-1][1] + GRIP)))


def check(scene) -> list[str]:
    problems = []
    fps = scene.render.fps / scene.render.fps_base
    frames = list(range(1, FRAMES + 1))
    names = ["Crate"] + [n for n, _ in pyramid()]
    m = _common.track(scene, names, frames)
    crate = m[:, 0, :3, 3]
    held = [gripper(scene, f) for f in range(1, RELEASE + 1)]
    off = np.linalg.norm(crate[:RELEASE] - np.array(held), axis=1)
    if off.max() > 1e-3:
        problems.append(f"the held crate is {off.max() * 1000:.1f} mm from the gripper at frame "
                        f"{int(np.argmax(off)) + 1}")
    g = np.array(scene.gravity)
    # the gripper's velocity when the crate is let go (the end of frame RELEASE's interval) and
    # the crate's over the next frame, gravity taken out (a parabola's chord: exact)
    dt = 1.0 / fps
    end = RELEASE + 1
    hand = (gripper(scene, end + 0.05) - gripper(scene, end - 0.05)) / (0.1 * dt)
    flight = (crate[end] - crate[end - 1]) / dt - 0.5 * g * dt
    if abs(np.linalg.norm(flight) / np.linalg.norm(hand) - 1.0) > RELEASE_TOLERANCE:
        problems.append(f"the crate left at {np.round(flight, 2)} m/s; the gripper moved at "
                        f"{np.round(hand, 2)} m/s")
    start, last = m[0, 1:], m[-1, 1:]
    moved = np.linalg.norm(last[:, :3, 3] - start[:, :3, 3], axis=1)
    tilt = np.degrees(np.arccos(np.clip(np.abs(last[:, 2, 2]), -1.0, 1.0)))
    knocked = (moved > KNOCKED) | (tilt > KNOCKED_DEG)
    if knocked.mean() < KNOCKED_SHARE:
        problems.append(f"only {int(knocked.sum())} of {len(knocked)} pyramid boxes knocked over")
    sizes = np.array([CRATE] + [BOX] * (len(names) - 1))
    low = m[:, :, 2, 3] - np.abs(m[:, :, 2, :3]).sum(axis=2) * sizes / 2
    if low.min() < -SINK:
        f, k = np.unravel_index(np.argmin(low), low.shape)
        problems.append(f'"{names[k]}" sank {-low.min() * 1000:.0f} mm into the ground at frame '
                        f"{frames[f]}")
    speed = np.linalg.norm(m[-1, :, :3, 3] - m[-2, :, :3, 3], axis=1) * fps
    if speed.max() > AT_REST:
        problems.append(f'"{names[int(np.argmax(speed))]}" still moves at {speed.max():.2f} m/s '
                        "at the end")
    return problems
