"""Cloth drape: a square cloth falls onto a sphere and the ground and settles in folds."""
from __future__ import annotations

import bpy
import numpy as np

from sample_scenes import _common

NAME = "cloth_drape"
RADIUS = 0.7
THICKNESS = 0.02  # keeps the cloth's flat faces from cutting into the curved ball


# Frames that show the point (falling over the ball with its corners flying; draping; settled
# in folds); README_FRAME is the README's picture.
SHOWCASE = (14, 22, 60)
README_FRAME = 14

def build(scene) -> None:
    import bmesh

    _common.stage(scene, (3.6, -4.2, 3.0), (0.0, 0.0, 0.6), frame_end=90)
    _common.ground(scene)
    ball = _common.add_mesh(scene, "Ball", lambda bm: bmesh.ops.create_uvsphere(
        bm, u_segments=48, v_segments=24, radius=1.0))
    for poly in ball.data.polygons:
        poly.use_smooth = True
    ball.scale = (RADIUS,) * 3
    ball.location = (0.0, 0.0, RADIUS)
    ball.data.materials.append(_common.material("Ball", (0.8, 0.35, 0.1)))
    ball.physanim.collider.enabled = True
    ball.physanim.collider.shape = 'SPHERE'
    ball.physanim.collider.restitution = 0.0
    ball.physanim.collider.friction = 0.4
    ball.physanim.collider.thickness = THICKNESS
    cloth = _common.grid(scene, "Cloth", 28, 28, 2.4)
    cloth.location = (0.0, 0.0, 1.9)
    for poly in cloth.data.polygons:
        poly.use_smooth = True
    cloth.data.materials.append(_common.material("Cloth", (0.2, 0.45, 0.85)))
    p = cloth.physanim.spring_mesh
    p.enabled = True
    p.mass = 0.6
    p.stiffness, p.damping = 30.0, 0.02
    p.shear_stiffness, p.shear_damping = 5.0, 0.005
    p.bend_mode, p.bend_stiffness, p.bend_damping = 'ANGULAR', 2e-4, 1e-5
    p.drag = 0.3
    ground = scene.objects["Ground"].physanim.collider
    ground.restitution, ground.friction, ground.thickness = 0.0, 0.6, 0.005
    scene.physanim.integrator = 'IMPLICIT'
    scene.physanim.spring_substeps = 2


def check(scene) -> list[str]:
    problems = []
    cloth = bpy.data.objects["Cloth"]
    center = np.array([0.0, 0.0, RADIUS])
    for frame in (30, 60, scene.physanim.frame_end):
        scene.frame_set(frame)
        x = _common.evaluated_vertices(cloth)
        r = np.linalg.norm(x - center, axis=1)
        if r.min() < RADIUS + THICKNESS - 0.002:
            problems.append(f"frame {frame}: cloth {RADIUS + THICKNESS - r.min():.3f} m closer "
                            "to the ball than its thickness")
        if x[:, 2].min() < -0.01:
            problems.append(f"frame {frame}: cloth {-x[:, 2].min():.3f} m below the ground")
    x = _common.evaluated_vertices(cloth)
    top = x[np.argmin(np.linalg.norm(x[:, :2], axis=1))]
    if abs(top[2] - 2 * RADIUS - THICKNESS) > 0.05:
        problems.append(f"the cloth's middle is at {top[2]:.2f} m, not resting on the ball "
                        f"top ({2 * RADIUS:.2f} m)")
    if x[:, 2].min() > 0.3:
        problems.append("the cloth's edges do not hang down towards the ground")
    return problems
