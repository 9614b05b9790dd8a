"""A wrecking ball: a chain of six steel links hangs from a crane's hook (a constraint to the
world), a heavy ball at its end; pulled back 60 degrees and let go, it swings into a wall of
concrete blocks and knocks it down. Every joint is a ball constraint between neighbours, made
as Connect Selected makes them (an Empty at each pivot).

Self-check: every joint holds (the ends of neighbouring links, the hook and the ball's eye
stay together to 5 mm in every frame), the ball knocks at least a third of the blocks off their
places, and no block or link sinks into the ground.
"""
from __future__ import annotations

import math

import bpy
import numpy as np
from mathutils import Matrix, Vector

from sample_scenes import _common

NAME = "wrecking_ball"
HOOK = np.array([0.0, 0.0, 5.2])  # [m] where the chain hangs from
LINKS = 6
LINK = 0.5  # [m] a link's length
LINK_MASS = 20.0  # [kg]
BALL_RADIUS = 0.5  # [m]
BALL_MASS = 1500.0  # [kg]
PULL = math.radians(60.0)  # how far the chain is pulled back from hanging straight down
BLOCK = 0.5  # [m] the wall's blocks
BLOCK_DENSITY = 2000.0  # [kg/m^3] concrete
WALL = (5, 5)  # blocks across, rows
WALL_X = 0.9  # [m] the wall's centre line
FRAMES = 120
HOLD = 0.005  # [m] how far a joint's two ends may come apart
KNOCKED = 0.2  # [m] a block counts as knocked off once moved this far ...
KNOCKED_SHARE = 1.0 / 3.0  # ... and at least this share of them must be
SINK = 0.01  # [m]

# pulled back (1), reaching the wall (26), breaking through (30), the wall down (90)
SHOWCASE = (1, 26, 30, 90)
README_FRAME = 30


def _direction() -> np.ndarray:
    """The chain's direction from the hook, pulled back (towards -x) by PULL."""
    return np.array([-math.sin(PULL), 0.0, -math.cos(PULL)])


def _links() -> list[str]:
    return [f"Link{i}" for i in range(LINKS)]


def _blocks() -> list[str]:
    return [f"Block{r}{c}" for r in range(WALL[1]) for c in range(WALL[0])]


def build(scene) -> None:
    import bmesh

    _common.stage(scene, (-7.0, -8.0, 4.0), (0.7, 0.0, 2.0), frame_end=FRAMES)
    _common.ground(scene)
    d = _direction()
    turn = Matrix.Rotation(PULL, 4, 'Y')  # the links' local Z up the chain (along -d)
    steel = _common.material("Steel", (0.55, 0.57, 0.6))
    pivots = [HOOK + d * LINK * i for i in range(LINKS + 1)]
    bodies = []
    for i, name in enumerate(_links()):
        ob = _common.add_mesh(scene, name, lambda bm: bmesh.ops.create_cube(
            bm, size=1.0, matrix=Matrix.Diagonal((0.1, 0.1, LINK * 0.98, 1.0))))
        ob.matrix_world = Matrix.Translation(Vector(pivots[i] + d * LINK / 2)) @ turn
        ob.data.materials.append(steel)
        ob.physanim.rigid_body.enabled = True
        ob.physanim.rigid_body.mass = LINK_MASS
        bodies.append(ob)
    ball = _common.add_mesh(scene, "Ball", lambda bm: bmesh.ops.create_uvsphere(
        bm, u_segments=32, v_segments=16, radius=BALL_RADIUS))
    ball.location = pivots[-1] + d * BALL_RADIUS
    ball.data.materials.append(_common.material("Ball", (0.12, 0.12, 0.13)))
    ball.physanim.rigid_body.enabled = True
    ball.physanim.rigid_body.mass = BALL_MASS
    bodies.append(ball)
    for i, pivot in enumerate(pivots):  # the hook, then each link to the next (or the ball)
        empty = bpy.data.objects.new(f"Joint{i}", None)
        empty.empty_display_size = 0.15
        empty.location = pivot
        scene.collection.objects.link(empty)
        c = empty.physanim.constraint
        c.enabled, c.type = True, 'BALL'
        c.object1 = bodies[i]
        if i:
            c.object1, c.object2 = bodies[i - 1], bodies[i]

    concrete = [_common.material(f"Concrete{k}", (0.62 + 0.08 * k, 0.6 + 0.06 * k, 0.55))
                for k in range(2)]
    for r in range(WALL[1]):
        for c in range(WALL[0]):
            ob = _common.add_mesh(scene, f"Block{r}{c}", lambda bm: bmesh.ops.create_cube(
                bm, size=BLOCK))
            ob.location = (WALL_X, (c - (WALL[0] - 1) / 2) * BLOCK * 1.01, BLOCK / 2 + r * BLOCK)
            ob.data.materials.append(concrete[(r + c) % 2])
            p = ob.physanim.rigid_body
            p.enabled, p.use_density, p.density = True, True, BLOCK_DENSITY


def check(scene) -> list[str]:
    problems = []
    m = _common.track(scene, _links() + ["Ball"] + _blocks(), range(1, FRAMES + 1))
    links, ball, blocks = m[:, :LINKS], m[:, LINKS], m[:, LINKS + 1:]
    axis = links[:, :, :3, 2]  # each link's Z: along the chain
    top = links[:, :, :3, 3] + axis * LINK * 0.5  # the end towards the hook (-d at the start)
    bottom = links[:, :, :3, 3] - axis * LINK * 0.5
    if np.dot(axis[0, 0], _direction()) > 0:  # local Z points down the chain: swap
        top, bottom = bottom, top
    eye = ball[:, :3, 3] - BALL_RADIUS * (ball[:, :3, 3] - bottom[:, -1]) / np.linalg.norm(
        ball[:, :3, 3] - bottom[:, -1], axis=1)[:, None]
    gaps = np.concatenate([np.linalg.norm(top[:, 0] - HOOK, axis=1)[:, None],
                           np.linalg.norm(top[:, 1:] - bottom[:, :-1], axis=2),
                           np.linalg.norm(eye - bottom[:, -1], axis=1)[:, None]], axis=1)
    if gaps.max() > HOLD:
        f, k = np.unravel_index(np.argmax(gaps), gaps.shape)
        problems.append(f"joint {k} opened {gaps.max() * 1000:.1f} mm at frame {f + 1}")
    moved = np.linalg.norm(blocks[-1, :, :3, 3] - blocks[0, :, :3, 3], axis=1)
    if (moved > KNOCKED).mean() < KNOCKED_SHARE:
        problems.append(f"only {int((moved > KNOCKED).sum())} of {len(moved)} blocks knocked off")
    low = blocks[:, :, 2, 3] - np.abs(blocks[:, :, 2, :3]).sum(axis=2) * BLOCK / 2
    if low.min() < -SINK:
        problems.append(f"a block sank {-low.min() * 1000:.0f} mm into the ground")
    return problems
