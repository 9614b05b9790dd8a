"""Rigid bodies: a ten-box tower and a pyramid of 21 boxes stand on the ground; a heavy ball
thrown at the pyramid knocks it over, and convex-hull rocks fall in a heap behind it. Self-check:
the tower stands still (its top drifts less than a millimetre once settled), the ball scatters
the pyramid, nothing sinks into the ground, and everything but the ball (and a box it still
pushes) comes to rest."""
from __future__ import annotations

import bpy
import numpy as np

from sample_scenes import _common

NAME = "rigid_bodies"
BOX = 0.4  # [m] edge of the tower's and pyramid's boxes
TOWER = 10
PYRAMID = 6  # boxes in the bottom row (6 + 5 + ... + 1 = 21)
BALL_RADIUS = 0.35  # [m]
AT_REST = 0.02  # [m/s] fastest a body may move at the end (but the ball and what it pushes)

# the ball on its way (24), hitting the pyramid (36), the pyramid scattered beside the standing
# tower and the rocks (90)
SHOWCASE = (24, 36, 90)
README_FRAME = 36


def _box(scene, name, location, color):
    import bmesh

    ob = _common.add_mesh(scene, name, lambda bm: bmesh.ops.create_cube(bm, size=BOX))
    ob.location = location
    ob.data.materials.append(color)
    ob.physanim.rigid_body.enabled = True
    return ob


def _rock(scene, name, location, seed):
    import bmesh

    rng = np.random.default_rng(seed)

    def make(bm):
        bmesh.ops.create_icosphere(bm, subdivisions=1, radius=0.3)
        for v in bm.verts:  # a lumpy rock: each vertex in or out a little
            v.co *= rng.uniform(0.7, 1.15)
        bmesh.ops.convex_hull(bm, input=bm.verts[:])
    ob = _common.add_mesh(scene, name, make)
    ob.location = location
    ob.data.materials.append(_common.material(f"{name}Stone", (0.45, 0.42, 0.38)))
    p = ob.physanim.rigid_body
    p.enabled, p.use_density, p.density = True, True, 500.0
    return ob


def build(scene) -> None:
    import bmesh

    _common.stage(scene, (8.0, -11.5, 5.0), (-0.2, 1.0, 1.5), frame_end=96)
    _common.ground(scene)
    wood = _common.material("Wood", (0.75, 0.5, 0.25))
    red = _common.material("Red", (0.8, 0.15, 0.1))
    for k in range(TOWER):
        _box(scene, f"Tower{k:02d}", (-1.8, 1.5, BOX / 2 + k * BOX), wood)
    for row in range(PYRAMID):
        for i in range(PYRAMID - row):
            x = (i - (PYRAMID - row - 1) / 2) * BOX * 1.02
            _box(scene, f"Pyramid{row}_{i}", (x, 0.0, BOX / 2 + row * BOX), red)
    ball = _common.add_mesh(scene, "Ball", lambda bm: bmesh.ops.create_uvsphere(
        bm, u_segments=24, v_segments=12, radius=BALL_RADIUS))
    for poly in ball.data.polygons:
        poly.use_smooth = True
    ball.location = (0.0, -6.0, 0.9)
    ball.data.materials.append(_common.material("Steel", (0.6, 0.6, 0.65)))
    p = ball.physanim.rigid_body
    p.enabled, p.mass = True, 40.0
    p.initial_velocity = (0.0, 8.0, 2.0)
    for k in range(4):
        _rock(scene, f"Rock{k}", (2.0 + 0.45 * k, 2.4 - 0.2 * k, 0.8 + 0.8 * k), seed=k)


def _track(scene, name, frames) -> np.ndarray:
    ob = bpy.data.objects[name]
    out = []
    for f in frames:
        scene.frame_set(f)
        out.append(np.array(ob.matrix_world.translation))
    return np.array(out)


def check(scene) -> list[str]:
    problems = []
    last = scene.physanim.frame_end
    top = _track(scene, f"Tower{TOWER - 1:02d}", range(30, last + 1))
    drift = float(np.linalg.norm(top - top[0], axis=1).max())
    if drift > 1e-3:
        problems.append(f"the tower swayed: its top moved {drift * 1000:.1f} mm after frame 30")
    moved = [float(np.linalg.norm(_track(scene, f"Pyramid{PYRAMID - 1}_0", [1, last])[1]
                                  - _track(scene, f"Pyramid{PYRAMID - 1}_0", [1, last])[0]))]
    if moved[0] < 0.3:
        problems.append("the ball did not knock the pyramid's top box off")
    bodies = [o for o in scene.objects if o.physanim.rigid_body.enabled]
    scene.frame_set(last)
    for ob in bodies:
        low = min((ob.matrix_world @ v.co).z for v in ob.data.vertices)
        if low < -0.01:
            problems.append(f'"{ob.name}" sank {-low * 1000:.0f} mm into the ground')
    names = [o.name for o in bodies]
    at = {n: np.array(bpy.data.objects[n].matrix_world.translation) for n in names}
    scene.frame_set(last - 1)
    speed = {n: np.linalg.norm(at[n] - np.array(bpy.data.objects[n].matrix_world.translation))
             * scene.render.fps for n in names}
    # the ball rolls on: a pyramid box it still pushes at the end (within touching distance
    # of it while it rolls) moves with it
    reach = BALL_RADIUS + BOX * np.sqrt(3.0) / 2 + 0.01
    pushed = {n for n in names if n.startswith("Pyramid") and speed["Ball"] > AT_REST
              and np.linalg.norm(at[n] - at["Ball"]) <= reach}
    moving = [n for n in names if n != "Ball" and n not in pushed and speed[n] > AT_REST]
    if moving:
        problems.append(f"still moving at the end: {', '.join(moving[:5])}")
    return problems
