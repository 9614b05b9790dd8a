"""Fountain: a nozzle sprays up, gravity and drag pull the water back, it bounces on the ground
with restitution and friction, and its color fades from white-blue to transparent over life."""
from __future__ import annotations

import math

import bpy
import numpy as np

from sample_scenes import _common

NAME = "fountain"
SPEED = 7.0


# Frames that show the point (the spray in full flow, bouncing and fading); README_FRAME is the
# README's picture.
SHOWCASE = (40, 80, 120)
README_FRAME = 80

def build(scene) -> None:
    _common.stage(scene, (9.0, -11.0, 5.0), (0.0, 0.0, 2.0), frame_end=120)
    _common.ground(scene)
    nozzle = bpy.data.objects.new("Fountain", None)
    nozzle.empty_display_type = 'CONE'
    nozzle.location = (0.0, 0.0, 0.3)
    scene.collection.objects.link(nozzle)
    p = nozzle.physanim.emitter
    p.enabled = True
    p.source = 'ORIGIN'
    p.direction = 'AXIS'
    p.axis = 'Z'
    p.spread = math.radians(12.0)
    p.rate, p.rate_random = 120.0, 30.0
    p.frame_start, p.frame_end = 1, 120
    p.lifetime, p.lifetime_random = 70.0, 10.0
    p.speed, p.speed_random = SPEED, 0.5
    p.size = 0.045
    p.color_stops[0].color = (0.75, 0.9, 1.0, 1.0)
    p.color_stops[1].color = (0.05, 0.3, 0.9, 0.0)
    p.size_stops[1].value = 0.6
    p.render_as = 'BILLBOARD'  # soft round drops of spray, facing the camera
    col = scene.objects["Ground"].physanim.collider
    col.restitution, col.friction = 0.45, 0.3
    drag = bpy.data.objects.new("Air", None)
    scene.collection.objects.link(drag)
    drag.physanim.force.enabled = True
    drag.physanim.force.type = 'DRAG'
    drag.physanim.force.linear = 0.01
    scene.physanim.substeps = 2


def check(scene) -> list[str]:
    """Self-check after a bake: what a viewer would notice if the physics were wrong."""
    problems = []
    g = abs(scene.gravity[2])
    life = bpy.data.objects["Fountain"].physanim.emitter.lifetime  # frames
    apex = SPEED ** 2 / (2 * g) + 0.6  # speed + random, nozzle height
    seen_bounce = False
    for frame in (20, 60, 100):
        pts = _common.points(scene, "Fountain", frame)
        z = pts["position"][:, 2]
        if len(z) == 0:
            problems.append(f"no particles at frame {frame}")
            continue
        if z.min() < -1e-3:
            problems.append(f"frame {frame}: a particle is {z.min():.4f} m below the ground")
        if z.max() > apex:
            problems.append(f"frame {frame}: particle at {z.max():.2f} m above the apex {apex:.2f} m")
        near = z < 0.05
        seen_bounce |= bool(np.any(pts["velocity"][near, 2] > 0.2))
        old = pts["age"] > 0.8 * life
        young = pts["age"] < 0.2 * life
        if old.any() and young.any() and not pts["color"][old, 3].mean() < pts["color"][young, 3].mean():
            problems.append(f"frame {frame}: old particles are not more transparent than young ones")
    if not seen_bounce:
        problems.append("no particle bounced off the ground")
    if len(np.unique(pts["id"])) != len(pts["id"]):
        problems.append("duplicate particle ids")
    # resting water slides to a stop: friction, not a frictionless skate across the ground
    resting = (pts["position"][:, 2] < 0.01) & (pts["age"] > 0.9 * life)
    if resting.any() and np.abs(pts["velocity"][resting, :2]).max() > SPEED:
        problems.append("particles on the ground slide faster than they were thrown")
    return problems
