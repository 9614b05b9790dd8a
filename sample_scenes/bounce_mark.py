"""A ball directed by the animator: thrown from a stand so that it flies through a hoop exactly at
frame 30 (Hit the Mark: the bake solves its launch), then bounces across the floor, squashing on
each bounce and stretching in flight (Squash & Stretch), with an antenna on top that trails it
and swings on after each landing (Follow-Through). The simulation itself stays rigid.

Self-check: the ball's centre is within 1 mm of the hoop's at frame 30; its scale keeps its
volume (product 1 within 1e-6) in every frame; it is squashed (below 0.9 along the floor's
normal) on at least two bounces; the antenna swings away from its rest on the ball by more than
5 cm after a landing and settles to under half that swing by the end.
"""
from __future__ import annotations

import math

import bpy
import numpy as np

from sample_scenes import _common

NAME = "bounce_mark"
RADIUS = 0.3  # [m]
START = (-6.0, 0.0, 1.8)
HOOP = (-1.5, 0.0, 3.2)  # the hoop's centre: the mark
HOOP_FRAME = 30
FRAMES = 96
ANTENNA = 0.7  # [m] above the ball's centre

# the throw (12), through the hoop (30), squashed off the floor (41), the next bounce (66)
SHOWCASE = (12, 30, 41, 66)
README_FRAME = 41


def build(scene) -> None:
    import bmesh

    _common.stage(scene, (-11.0, -12.0, 4.0), (0.5, 0.0, 1.6), frame_end=FRAMES)
    floor = _common.ground(scene, color=(0.3, 0.32, 0.35))
    floor.physanim.collider.restitution, floor.physanim.collider.friction = 0.8, 0.0
    red = _common.material("BallRed", (0.8, 0.1, 0.08))
    gold = _common.material("Hoop", (0.9, 0.65, 0.15), emission=0.3)
    ball = _common.add_mesh(scene, "Ball", lambda bm: bmesh.ops.create_uvsphere(
        bm, u_segments=32, v_segments=16, radius=RADIUS))
    ball.data.materials.append(red)
    for face in ball.data.polygons:
        face.use_smooth = True
    ball.location = START
    p = ball.physanim.rigid_body
    p.enabled = True
    p.shape = 'SPHERE'
    p.restitution, p.friction = 0.75, 0.0
    p.angular_damping = 200.0  # a weighted toy: it stays upright, its antenna on top
    p.squash = 1.2
    hoop = _common.add_mesh(scene, "Hoop", _torus)
    hoop.location = HOOP
    hoop.rotation_euler = (0.0, math.radians(90.0), 0.0)  # the ball flies through along x
    hoop.data.materials.append(gold)
    p.target, p.target_frame = hoop, HOOP_FRAME
    antenna = _common.add_mesh(scene, "Antenna", lambda bm: bmesh.ops.create_cone(
        bm, cap_ends=True, segments=12, radius1=0.06, radius2=0.0, depth=0.5))
    antenna.data.materials.append(gold)
    antenna.parent = ball
    antenna.location = (0.0, 0.0, ANTENNA)
    antenna.physanim.follow.enabled = True
    antenna.physanim.follow.frequency, antenna.physanim.follow.damping = 2.5, 0.15


def _torus(bm, major: float = 0.55, minor: float = 0.04, around: int = 48,
           across: int = 10) -> None:
    """A ring about the local Z axis (quads)."""
    verts = []
    for i in range(around):
        a = 2 * math.pi * i / around
        for j in range(across):
            b = 2 * math.pi * j / across
            r = major + minor * math.cos(b)
            verts.append(bm.verts.new((r * math.cos(a), r * math.sin(a), minor * math.sin(b))))
    for i in range(around):
        for j in range(across):
            k = lambda i_, j_: verts[(i_ % around) * across + j_ % across]  # noqa: E731
            bm.faces.new((k(i, j), k(i + 1, j), k(i + 1, j + 1), k(i, j + 1)))


def check(scene) -> list[str]:
    problems = []
    ball, hoop = bpy.data.objects["Ball"], bpy.data.objects["Hoop"]
    antenna = bpy.data.objects["Antenna"]
    scene.frame_set(HOOP_FRAME)
    miss = (ball.matrix_world.translation - hoop.matrix_world.translation).length
    if miss > 1e-3:
        problems.append(f"the ball misses the hoop's centre by {1000 * miss:.1f} mm at frame "
                        f"{HOOP_FRAME}")
    squashes, swing, heights = [], [], []
    for frame in range(1, FRAMES + 1):
        scene.frame_set(frame)
        scale = np.array(ball.scale)
        if abs(np.prod(scale) - 1.0) > 1e-6:
            problems.append(f"frame {frame}: the ball's volume changed (scale {scale.tolist()})")
        world = np.array(ball.matrix_world.to_3x3())
        squashes.append(float(np.linalg.norm(world[2])))  # its extent along the floor's normal
        rest = np.array(ball.matrix_world.translation) + world @ np.array((0.0, 0.0, ANTENNA))
        swing.append(float(np.linalg.norm(np.array(antenna.matrix_world.translation) - rest)))
        heights.append(ball.matrix_world.translation.z)
    squashes = np.array(squashes)
    bounces = [k for k in range(1, FRAMES - 1) if squashes[k] < 0.9
               and squashes[k] <= squashes[k - 1] and squashes[k] <= squashes[k + 1]]
    if len(bounces) < 2:
        problems.append(f"squashed below 0.9 on {len(bounces)} bounce(s), not 2 or more")
    if max(swing) < 0.05:
        problems.append(f"the antenna swings at most {max(swing):.3f} m off its rest")
    if swing[-1] > 0.5 * max(swing):
        problems.append(f"the antenna is still {swing[-1]:.3f} m off its rest at the end (its "
                        f"largest swing: {max(swing):.3f} m)")
    return problems
