"""Fireworks: rockets launched from the ground burst, where they die, into colored sparks that
inherit the rocket's velocity, fall under gravity and drag, and fade out."""
from __future__ import annotations

import math

import bpy
import numpy as np

from sample_scenes import _common

NAME = "fireworks"


def build(scene) -> None:
    _common.stage(scene, (0.0, -75.0, 14.0), (0.0, 0.0, 20.0), frame_end=150)
    scene.world.color = (0.005, 0.005, 0.015)
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
    r.stretch = 0.08
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
    s.stretch = 0.05
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
    problems = []
    first_spark = None
    for frame in range(1, scene.physanim.frame_end + 1, 5):
        sp = _common.points(scene, "Sparks", frame)
        if len(sp["id"]) and first_spark is None:
            first_spark = frame
            rockets_before = _common.points(scene, "Rockets", frame - 5)
            # sparks are born where a rocket died: near a rocket's last known position/path
            d = np.linalg.norm(sp["position"][:, None, :] - rockets_before["position"][None], axis=2)
            if len(rockets_before["id"]) and d.min(axis=1).max() > 25.0:
                problems.append("sparks appeared far from every rocket")
    if first_spark is None:
        problems.append("no sparks: rockets never burst")
        return problems
    if first_spark < 30:
        problems.append(f"sparks appeared at frame {first_spark}, before any rocket could die")
    sp = _common.points(scene, "Sparks", first_spark + 10)
    if len(sp["id"]) < 100:
        problems.append(f"only {len(sp['id'])} sparks 10 frames after the first burst")
    if sp["position"][:, 2].max() < 5.0:
        problems.append("bursts happen near the ground instead of in the sky")
    return problems
