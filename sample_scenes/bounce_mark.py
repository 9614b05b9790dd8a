"""A ball directed by the animator: thrown from a stand so that it flies through a hoop exactly at
frame 30 (Hit the Mark: the bake solves its launch), in slow motion there (the scene's Time
Scale keyed down to 0.3 around the hoop and back up), then bounces across the floor, lingering at
the top of each bounce (Hang Time), squashing on each landing and stretching in flight (Squash &
Stretch), with an antenna on top that trails it and swings on after each landing
(Follow-Through). A burst of confetti fired from a cannon flies through a second ring at the
same frame (Hit the Mark for a particle burst). The simulation itself stays rigid.

Self-check: the ball's centre is within 1 mm of the hoop's at frame 30, and the confetti's
centre within 1 mm of the ring's; the ball moves less than half as far per frame through the
hoop as before the slow motion; its scale keeps its volume (product 1 within 1e-6) in every
frame; it is squashed (below 0.9 along the floor's normal) on at least two bounces; the antenna
swings away from its rest on the ball by more than 5 cm after a landing and settles to under
half that swing by the end.
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
RING = (-2.2, 2.4, 2.7)  # the confetti's mark
CANNON = (-5.5, 2.4, 0.3)
FRAMES = 104
# Time Scale keys (frame, scale): slow motion through the hoop
TIME_KEYS = ((1, 1.0), (22, 1.0), (28, 0.3), (33, 0.3), (42, 1.0))
ANTENNA = 0.7  # [m] above the ball's centre

# the throw and the confetti's burst (14), ball and confetti through their rings in slow motion
# (30), squashed off the floor (49), lingering in a bounce (70)
SHOWCASE = (14, 30, 49, 70)
README_FRAME = 30


def build(scene) -> None:
    import bmesh

    _common.stage(scene, (-9.0, -11.5, 3.6), (-1.3, 1.0, 2.0), frame_end=FRAMES)
    floor = _common.ground(scene, size=60.0, color=(0.3, 0.32, 0.35))
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
    p.hang_time = 0.35  # the flight to the hoop stays as solved: the bounces after linger
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
    antenna.physanim.follow.frequency, antenna.physanim.follow.damping = 4.5, 0.25
    _confetti(scene, gold)
    for frame, value in TIME_KEYS:
        scene.physanim.time_scale = value
        scene.physanim.keyframe_insert("time_scale", frame=frame)
    scene.physanim.time_scale = 1.0


def _confetti(scene, gold) -> None:
    """A cannon's one-frame burst aimed through a ring at the hoop's frame."""
    import bmesh

    ring = _common.add_mesh(scene, "Ring", lambda bm: _torus(bm, major=0.4))
    ring.location = RING
    ring.rotation_euler = (0.0, math.radians(90.0), 0.0)
    ring.data.materials.append(gold)
    cannon = _common.add_mesh(scene, "Cannon", lambda bm: bmesh.ops.create_cone(
        bm, cap_ends=True, segments=16, radius1=0.18, radius2=0.12, depth=0.5))
    cannon.location = CANNON
    cannon.rotation_euler = (0.0, math.radians(40.0), 0.0)
    cannon.data.materials.append(_common.material("Cannon", (0.1, 0.1, 0.12)))
    e = cannon.physanim.emitter
    e.enabled = True
    e.source, e.direction = 'ORIGIN', 'NORMAL'
    e.rate, e.frame_start, e.frame_end = 60.0, 10, 10
    e.spread = math.radians(7.0)
    e.lifetime = 90.0
    e.size, e.size_random = 0.05, 0.015
    e.seed = 5
    e.color_stops[0].color = (0.2, 0.8, 1.0, 1.0)
    e.color_stops[1].color = (1.0, 0.3, 0.7, 1.0)
    e.target, e.target_frame = ring, HOOP_FRAME


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


def _check_confetti(scene) -> list[str]:
    """The centre of the burst's particles at the hoop's frame is on the ring's."""
    from sample_scenes._common import result_points

    cannon, ring = bpy.data.objects["Cannon"], bpy.data.objects["Ring"]
    scene.frame_set(HOOP_FRAME)
    points = result_points(cannon.physanim.emitter.result)
    if not len(points.get("position", ())):
        return [f"no confetti at frame {HOOP_FRAME}"]
    miss = float(np.linalg.norm(points["position"].mean(axis=0)
                                - np.array(ring.matrix_world.translation)))
    if miss > 1e-3:
        return [f"the confetti's centre misses the ring's by {1000 * miss:.1f} mm at frame "
                f"{HOOP_FRAME}"]
    return []


def check(scene) -> list[str]:
    problems = []
    ball, hoop = bpy.data.objects["Ball"], bpy.data.objects["Hoop"]
    antenna = bpy.data.objects["Antenna"]
    scene.frame_set(HOOP_FRAME)
    miss = (ball.matrix_world.translation - hoop.matrix_world.translation).length
    if miss > 1e-3:
        problems.append(f"the ball misses the hoop's centre by {1000 * miss:.1f} mm at frame "
                        f"{HOOP_FRAME}")
    problems += _check_confetti(scene)
    steps = {}
    for a in (18, HOOP_FRAME - 1):
        scene.frame_set(a)
        before = np.array(ball.matrix_world.translation)
        scene.frame_set(a + 2)
        steps[a] = float(np.linalg.norm(np.array(ball.matrix_world.translation) - before))
    if steps[HOOP_FRAME - 1] > 0.5 * steps[18]:
        problems.append(f"no slow motion at the hoop: {steps[HOOP_FRAME - 1]:.3f} m in two "
                        f"frames there, {steps[18]:.3f} m before")
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
