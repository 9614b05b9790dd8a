"""Robot arm throw: a three-joint arm (base yaw, shoulder, elbow) swings; particles born at its
tip leave with the tip's own velocity dQ/dt (inherit_velocity = 1), like a thrown ball."""
from __future__ import annotations

import math

import bpy
import numpy as np

from sample_scenes import _common

NAME = "robot_arm"
SEGMENTS = (("Base", 0.6), ("UpperArm", 2.0), ("Forearm", 1.6))


# Frames that show the point (mid-whip, the ball just thrown, the next wind-up (its motion repeats
# every 40 frames)); README_FRAME is the README's picture.
SHOWCASE = (64, 70, 100)
README_FRAME = 70


def build(scene) -> None:
    _common.stage(scene, (6.0, -14.0, 5.0), (3.0, 0.0, 2.0), frame_end=120)
    _common.ground(scene)
    joints = _common.robot_arm(scene, SEGMENTS)
    base, upper, fore = joints
    # a throwing motion, repeated: wind up slowly, whip forward fast
    cycle = 40
    for start in range(0, 121, cycle):
        _common.key_values(base, "rotation_euler", 2, [(start + 1, 0.0), (start + 20, math.radians(-25)),
                                         (start + 28, math.radians(20)), (start + cycle, 0.0)])
        _common.key_values(upper, "rotation_euler", 1, [(start + 1, math.radians(-20)),
                                          (start + 20, math.radians(-70)),
                                          (start + 28, math.radians(50)),
                                          (start + cycle, math.radians(-20))])
        _common.key_values(fore, "rotation_euler", 1, [(start + 1, math.radians(10)),
                                         (start + 20, math.radians(-60)),
                                         (start + 28, math.radians(40)),
                                         (start + cycle, math.radians(10))])
    tip = bpy.data.objects.new("Tip", None)
    tip.parent = fore
    tip.location = (0.0, 0.0, SEGMENTS[2][1])
    tip.empty_display_size = 0.2
    scene.collection.objects.link(tip)
    p = tip.physanim.emitter
    p.enabled = True
    p.source, p.direction = 'ORIGIN', 'RANDOM'
    p.rate, p.rate_random = 25.0, 5.0
    p.frame_start, p.frame_end = 1, 120
    p.speed, p.speed_random = 0.0, 0.0
    p.inherit_velocity = 1.0
    p.lifetime = 60.0
    p.size = 0.06
    p.color_stops[0].color = (0.2, 0.9, 0.4, 1.0)
    p.color_stops[1].color = (0.1, 0.4, 1.0, 0.3)
    col = scene.objects["Ground"].physanim.collider
    col.restitution, col.friction = 0.3, 0.6
    scene.physanim.substeps = 4


def tip_velocity(scene, frame: float) -> np.ndarray:
    """Central-difference world velocity of the tip [m/s] at ``frame``."""
    fps = scene.render.fps / scene.render.fps_base
    tip = bpy.data.objects["Tip"]
    pos = []
    for f in (frame - 0.05, frame + 0.05):
        scene.frame_set(int(math.floor(f)), subframe=f - math.floor(f))
        pos.append(np.array(tip.matrix_world.translation))
    return (pos[1] - pos[0]) / (0.1 / fps)


def check(scene) -> list[str]:
    """Particles just born carry the tip's dQ/dt (within the one-frame sampling error)."""
    problems = []
    fps = scene.render.fps / scene.render.fps_base
    g = np.array(scene.gravity)
    for frame in (24, 27, 64, 67):
        pts = _common.points(scene, "Tip", frame)
        young = pts["age"] < 0.5
        if not young.any():
            problems.append(f"frame {frame}: no newborn particles")
            continue
        v_birth = pts["velocity"][young] - g * (pts["age"][young, None] / fps)
        expected = tip_velocity(scene, frame - float(pts["age"][young].mean()))
        err = np.linalg.norm(v_birth.mean(axis=0) - expected)
        if err > 0.15 * max(1.0, np.linalg.norm(expected)):
            problems.append(f"frame {frame}: newborn velocity {v_birth.mean(axis=0).round(2)} is not "
                            f"the tip velocity {expected.round(2)}")
    return problems
