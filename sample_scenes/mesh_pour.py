"""Particles pour onto a spinning Suzanne and a bumpy ground whose waves keep travelling: any
mesh is a collider — here the evaluated mesh of a Wave modifier and an animated object —
sampled every frame."""
from __future__ import annotations

import math

import bpy

from sample_scenes import _common

NAME = "mesh_pour"


# Frames that show the point (particles landing on the spinning Suzanne and the travelling waves);
# README_FRAME is the README's picture.
SHOWCASE = (25, 50, 75)
README_FRAME = 50

def build(scene) -> None:
    import bmesh

    _common.stage(scene, (5.5, -7.5, 4.5), (0.0, 0.0, 1.0), frame_end=80)
    ground = _common.grid(scene, "Bumps", 60, 60, 8.0)
    ground.data.materials.append(_common.material("Bumps", (0.25, 0.3, 0.35)))
    for poly in ground.data.polygons:
        poly.use_smooth = True
    wave = ground.modifiers.new("Waves", 'WAVE')
    wave.height, wave.width, wave.narrowness, wave.speed = 0.25, 1.5, 0.5, 0.04  # travelling
    g = ground.physanim.collider
    g.enabled, g.shape, g.restitution, g.friction = True, 'MESH', 0.3, 0.4
    monkey = _common.add_mesh(scene, "Suzanne", lambda bm: bmesh.ops.create_monkey(bm))
    for poly in monkey.data.polygons:
        poly.use_smooth = True
    monkey.location = (0.0, 0.0, 1.2)
    monkey.rotation_mode = 'XYZ'
    monkey.data.materials.append(_common.material("Suzanne", (0.85, 0.55, 0.15)))
    for frame, angle in ((1, 0.0), (80, 2 * math.pi)):
        monkey.rotation_euler = (0.0, 0.0, angle)
        monkey.keyframe_insert("rotation_euler", index=2, frame=frame)
    m = monkey.physanim.collider
    m.enabled, m.shape, m.restitution, m.friction = True, 'MESH', 0.2, 0.5
    spout = _common.add_mesh(scene, "Spout", lambda bm: bmesh.ops.create_circle(
        bm, cap_ends=True, segments=16, radius=0.5))
    spout.location = (0.2, 0.1, 4.0)
    spout.rotation_euler = (math.pi, 0.0, 0.0)  # faces down
    spout.hide_render = True
    p = spout.physanim.emitter
    p.enabled = True
    p.source, p.direction = 'FACES', 'NORMAL'
    p.rate, p.rate_random = 30.0, 5.0
    p.frame_start, p.frame_end = 1, 70
    p.speed, p.speed_random, p.spread = 1.0, 0.3, math.radians(10.0)
    p.lifetime = 100.0
    p.size = 0.04
    p.color_stops[0].color = (0.9, 0.95, 1.0, 1.0)
    p.color_stops[1].color = (0.3, 0.6, 1.0, 1.0)
    p.render_as, p.blob_size, p.blob_resolution = 'BLOBS', 1.8, 4.0  # a liquid's surface
    scene.physanim.substeps = 3


def check(scene) -> list[str]:
    from mathutils import Vector
    from mathutils.bvhtree import BVHTree

    problems = []
    ground = bpy.data.objects["Bumps"]
    monkey = bpy.data.objects["Suzanne"]
    on_monkey = 0
    for frame in (30, 55, 80):
        pts = _common.points(scene, "Spout", frame)
        if len(pts["id"]) == 0:
            problems.append(f"frame {frame}: no particles")
            continue
        depsgraph = bpy.context.evaluated_depsgraph_get()
        surface = BVHTree.FromObject(ground, depsgraph)
        head = BVHTree.FromObject(monkey, depsgraph)
        m_ground = ground.matrix_world.inverted()
        below = 0
        for x in pts["position"]:
            local = m_ground @ Vector(x)
            hit, *_ = surface.ray_cast(local, Vector((0.0, 0.0, 1.0)), 10.0)
            below += hit is not None  # the ground is above this particle: it fell through
        if below > len(pts["id"]) // 200:  # a known rare case next to grid edges (see tests)
            problems.append(f"frame {frame}: {below} of {len(pts['id'])} particles under the "
                            "bumpy ground")
        m_head = monkey.matrix_world.inverted()
        near = [head.find_nearest(m_head @ Vector(x), 0.06)[0] for x in pts["position"]]
        on_monkey += sum(n is not None for n in near)
    if on_monkey == 0:
        problems.append("no particle ever lands on Suzanne")
    return problems
