"""Newton's cradle: five steel balls hang 1 mm apart from hinge constraints on a frame (each
ball's string is a child object, carried by the baked ball); the first is pulled out 30
degrees and let go. It stops dead on the row and the last ball flies out, swings back, and the
first goes out again: the impact passes along the row one ball to the next. The balls are
rigid bodies with restitution 1 and no friction (polished steel); everything else is the
default.

Self-check: the last ball rises to at least 90 % of the first one's drop, the first stops on
the row (it rises at most 5 % of it after the impact), the middle three barely stir (2 mm), and
no two balls overlap by more than 1 mm.
"""
from __future__ import annotations

import math

import bpy
import numpy as np

from sample_scenes import _common

NAME = "newtons_cradle"
BALLS = 5
RADIUS = 0.1  # [m]
GAP = 0.001  # [m] between neighbouring balls
LENGTH = 0.8  # [m] from a hinge to its ball's centre
TOP = 1.2  # [m] the hinges' height
PULL = math.radians(30.0)
FRAMES = 72
RISE = 0.9  # the last ball rises at least this share of the first one's drop
STIR = 0.002  # [m] the middle balls' largest rise
OVERLAP = 0.001  # [m]

# let go (1), the impact (14), the last ball out (26), the first one out again (50)
SHOWCASE = (1, 14, 26, 50)
README_FRAME = 26


def _x(i: int) -> float:
    return (i - (BALLS - 1) / 2) * (2 * RADIUS + GAP)


def build(scene) -> None:
    import bmesh
    from mathutils import Matrix

    _common.stage(scene, (0.0, -3.2, 1.0), (0.0, 0.0, 0.75), frame_end=FRAMES)
    _common.ground(scene)
    steel = _common.material("Steel", (0.75, 0.77, 0.8))
    frame_mat = _common.material("Frame", (0.15, 0.15, 0.17))
    for y in (-0.25, 0.25):  # the frame's two top bars (not simulated)
        bar = _common.add_mesh(scene, f"Bar{'L' if y < 0 else 'R'}", lambda bm: bmesh.ops.create_cube(
            bm, size=1.0, matrix=Matrix.Diagonal((1.4, 0.03, 0.03, 1.0))))
        bar.location = (0.0, y, TOP)
        bar.data.materials.append(frame_mat)
    for i in range(BALLS):
        out = -PULL if i == 0 else 0.0
        ball = _common.add_mesh(scene, f"Ball{i}", lambda bm: bmesh.ops.create_uvsphere(
            bm, u_segments=32, v_segments=16, radius=RADIUS))
        ball.location = (_x(i) + LENGTH * math.sin(out), 0.0, TOP - LENGTH * math.cos(out))
        ball.data.materials.append(steel)
        p = ball.physanim.rigid_body
        p.enabled, p.restitution, p.friction = True, 1.0, 0.0
        for side in (-1.0, 1.0):  # the strings, up to the two bars, carried by the ball
            string = _common.add_mesh(scene, f"String{i}{'LR'[side > 0]}", _string_mesh(side))
            string.data.materials.append(frame_mat)
            string.parent = ball
            string.rotation_euler = (0.0, -out, 0.0)  # hanging from the bar at the start
        hinge = bpy.data.objects.new(f"Hinge{i}", None)
        hinge.empty_display_size = 0.05
        hinge.location = (_x(i), 0.0, TOP)
        hinge.rotation_euler = (-math.pi / 2, 0.0, 0.0)  # its Z along +Y: the bars' direction
        scene.collection.objects.link(hinge)
        c = hinge.physanim.constraint
        c.enabled, c.type, c.object1 = True, 'HINGE', ball


def _string_mesh(side: float):
    """A thin rod from the ball's centre to the bar at y = 0.25 * side (in the ball's frame)."""
    import bmesh
    from mathutils import Matrix, Vector

    top = Vector((0.0, 0.25 * side, LENGTH))
    length = top.length
    rotation = Vector((0.0, 0.0, 1.0)).rotation_difference(top).to_matrix().to_4x4()

    def make(bm):
        bmesh.ops.create_cone(bm, cap_ends=True, segments=8, radius1=0.003, radius2=0.003,
                              depth=length, matrix=rotation @ Matrix.Translation(
                                  (0.0, 0.0, length / 2)))
    return make


def check(scene) -> list[str]:
    problems = []
    balls = [bpy.data.objects[f"Ball{i}"] for i in range(BALLS)]
    x = []
    for f in range(1, FRAMES + 1):
        scene.frame_set(f)
        x.append([np.array(b.matrix_world.translation) for b in balls])
    x = np.array(x)  # (frames, balls, 3)
    rise = x[:, :, 2] - (TOP - LENGTH)
    drop = LENGTH * (1 - math.cos(PULL))
    hit, back = 14, 32  # after the impact (frame 12); before the last ball is back (34)
    if rise[:back, -1].max() < RISE * drop:
        problems.append(f"the last ball rose {rise[:back, -1].max() * 1000:.0f} mm, less than "
                        f"{RISE:.0%} of the first one's {drop * 1000:.0f} mm drop")
    if rise[hit:back, 0].max() > 0.05 * drop:
        problems.append(f"the first ball did not stop on the row (rose "
                        f"{rise[hit:back, 0].max() * 1000:.0f} mm after the impact)")
    if np.abs(rise[:back, 1:-1]).max() > STIR:
        problems.append(f"a middle ball moved {np.abs(rise[:back, 1:-1]).max() * 1000:.1f} mm")
    apart = np.linalg.norm(x[:, 1:] - x[:, :-1], axis=2) - 2 * RADIUS
    if apart.min() < -OVERLAP:
        problems.append(f"two balls overlapped by {-apart.min() * 1000:.1f} mm")
    return problems
