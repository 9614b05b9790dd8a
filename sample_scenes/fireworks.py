"""Fireworks: rockets launched from the ground burst, where they die, into colored sparks that
inherit the rocket's velocity, fall under gravity and drag, and fade out."""
from __future__ import annotations

import math

import bpy
import numpy as np

from sample_scenes import _common

NAME = "fireworks"


# Frames that show the point (rockets bursting into sparks at different ages); README_FRAME is the
# README's picture.
SHOWCASE = (60, 100, 140)
README_FRAME = 100

def build(scene) -> None:
    _common.stage(scene, (0.0, -75.0, 14.0), (0.0, 0.0, 20.0), frame_end=150)
    scene.world.color = (0.005, 0.005, 0.015)
    scene.cycles.transparent_max_bounces = 128  # every glow a ray passes is one bounce
    _common.ground(scene, size=60.0, color=(0.05, 0.05, 0.06))
    launcher = bpy.data.objects.new("Rockets", None)
    scene.collection.objects.link(launcher)
    r = launcher.physanim.emitter
    r.enabled = True
    r.source, r.direction, r.axis = 'ORIGIN', 'AXIS', 'Z'
    r.spread = math.radians(14.0)
    r.rate, r.rate_random = 0.12, 0.12
    r.frame_start, r.frame_end = 1, 100
    r.speed, r.speed_random = 22.0, 2.0
    r.lifetime, r.lifetime_random = 40.0, 6.0
    r.size = 0.15
    r.mass = 1.0
    r.seed = 3
    r.color_stops[0].color = (1.0, 0.8, 0.4, 1.0)
    r.color_stops[1].color = (1.0, 0.5, 0.1, 1.0)
    r.render_as, r.streak_time = 'STREAKS', 0.12  # trails behind the rising rockets
    sparks = bpy.data.objects.new("Sparks", None)
    scene.collection.objects.link(sparks)
    s = sparks.physanim.emitter
    s.enabled = True
    s.source, s.parent, s.direction = 'DEATHS', launcher, 'RANDOM'
    s.rate, s.rate_random = 300.0, 50.0
    s.speed, s.speed_random = 7.0, 1.5
    s.inherit_velocity = 1.0
    s.lifetime, s.lifetime_random = 45.0, 12.0
    s.size, s.size_random = 0.12, 0.04
    s.mass = 0.05
    s.render_as, s.glow_strength = 'GLOW', 25.0  # sparks: light without a body, adding up
    s.seed = 7
    s.color_stops.clear()
    for pos, col in ((0.0, (1.0, 1.0, 0.9, 1.0)), (0.15, (1.0, 0.3, 0.6, 1.0)),
                     (0.6, (0.3, 0.4, 1.0, 0.8)), (1.0, (0.1, 0.1, 0.6, 0.0))):
        stop = s.color_stops.add()
        stop.position, stop.color = pos, col
    air = bpy.data.objects.new("Air", None)
    scene.collection.objects.link(air)
    air.physanim.force.enabled = True
    air.physanim.force.type = 'DRAG'
    air.physanim.force.linear = 0.03
    scene.physanim.seed = 11


def check(scene) -> list[str]:
    """Sparks are born where a rocket dies, carry its velocity, and burst high in the sky."""
    problems = []
    fps = scene.render.fps / scene.render.fps_base
    rocket_speed = 24.0  # speed + speed_random
    spark_speed = 8.5
    bursts = 0
    previous = _common.points(scene, "Rockets", 1)
    for frame in range(2, scene.physanim.frame_end + 1):
        sparks = _common.points(scene, "Sparks", frame)
        newborn = sparks["age"] < 1.0
        rockets = previous
        previous = _common.points(scene, "Rockets", frame)
        if not newborn.any():
            continue
        bursts += 1
        if frame < 30:
            problems.append(f"sparks appeared at frame {frame}, before any rocket could die")
        gone = ~np.isin(rockets["id"], previous["id"])  # rockets that died this frame
        if not gone.any():
            problems.append(f"frame {frame}: sparks were born but no rocket died")
            continue
        # a spark is within one frame of flight of a dying rocket's last position
        reach = (rocket_speed + spark_speed) / fps + 0.5
        d = np.linalg.norm(sparks["position"][newborn, None, :]
                           - rockets["position"][None, gone, :], axis=2).min(axis=1)
        if d.max() > reach:
            problems.append(f"frame {frame}: a newborn spark is {d.max():.1f} m from every dying "
                            f"rocket (reach {reach:.1f} m)")
        if rockets["position"][gone, 2].min() < 5.0:
            problems.append(f"frame {frame}: a rocket burst near the ground")
        if gone.sum() == 1:  # one burst: its sparks inherit the rocket's velocity on average
            mean_v = sparks["velocity"][newborn].mean(axis=0)
            rocket_v = rockets["velocity"][gone][0]
            spread = spark_speed / np.sqrt(newborn.sum()) * 3 + 9.81 / fps * 2
            if np.linalg.norm(mean_v - rocket_v) > spread + 1.0:
                problems.append(f"frame {frame}: sparks' mean velocity {mean_v.round(1)} is not "
                                f"the rocket's {rocket_v.round(1)}")
    if bursts == 0:
        problems.append("no sparks: rockets never burst")
    return problems
