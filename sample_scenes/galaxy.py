"""Galaxy collision: two spinning disks of stars (100,000 in all) fly at each other under their
own mutual gravity (Barnes-Hut), pass through each other and fling out tidal tails.

Each galaxy is a one-frame burst filling a flattened sphere (an oblate spheroid, axis ratio
0.3) that spins and moves: the stars inherit the emitter's velocity where they are born
(Inherit Velocity 1), plus a little random motion. Inside a uniform spheroid gravity grows
linearly with the distance from the axis (Maclaurin), so solid rotation at omega is an
equilibrium: omega^2 = 1.693 G M / R^3 for this flattening. The two close in at 3 m/s.
Rendered as glowing points.

Self-check: the two disks' centres of mass come within a third of their starting distance of
each other (they collide), the centre of mass of all the stars moves on the straight line its
starting momentum sets (the tree code's forces are equal and opposite to its error) within 1 %
of that distance,
and at the end at least 2 % of the stars have been thrown farther than twice a disk's radius
from both centres (tidal tails).
"""
from __future__ import annotations

import math

import bpy
import numpy as np

from sample_scenes import _common

NAME = "galaxy"
STARS = 100_000  # in both disks
RADIUS = 3.0  # [m] of each disk
OMEGA = 1.5  # [rad/s] each disk's spin
SPEED = 1.5  # [m/s] each disk's speed towards the other
FLATTENING = 0.3  # the spheroid's axis ratio
MACLAURIN = 1.693  # omega^2 R^3 / (G M) of solid rotation in equilibrium at this flattening
FRAMES = 120
STARTS = ((-6.0, -1.5, 0.0), (6.0, 1.5, 0.0))
# the test suite bakes this scene with fewer stars (same code, same self-check)
SUITE_ARGS = {"stars": 4000}

# Frames that show the point: the approach (20), through each other (60), the tails (120)
SHOWCASE = (20, 60, 120)
README_FRAME = 60


def build(scene, stars: int = STARS) -> None:
    import bmesh

    _common.stage(scene, (0.0, -9.0, 26.0), (0.0, 0.0, 0.0), frame_end=FRAMES)
    scene.world.color = (0.002, 0.002, 0.006)
    scene.cycles.transparent_max_bounces = 64  # glows overlap
    scene.use_gravity = False
    scene.physanim.substeps = 1
    fps = scene.render.fps / scene.render.fps_base
    mass = 1.0
    G = OMEGA ** 2 * RADIUS ** 3 / (MACLAURIN * mass * stars / 2)
    for k, (start, colours, spin) in enumerate((
            (STARTS[0], ((0.6, 0.8, 1.0, 1.0), (0.3, 0.5, 1.0, 1.0)), 1.0),
            (STARTS[1], ((1.0, 0.85, 0.6, 1.0), (1.0, 0.5, 0.3, 1.0)), -1.0))):
        disk = _common.add_mesh(scene, f"Galaxy{k + 1}", lambda bm: bmesh.ops.create_uvsphere(
            bm, u_segments=48, v_segments=24, radius=RADIUS))
        disk.scale = (1.0, 1.0, FLATTENING)
        disk.hide_render = True
        disk.display_type = 'WIRE'
        direction = -np.sign(start[0])
        # the emitter spins and flies at constant rates (linear keys); the burst at frame 1
        # inherits both
        for frame in (0, FRAMES):
            t = frame / fps
            disk.location = (start[0] + direction * SPEED * t, start[1], start[2])
            disk.rotation_euler = (0.0, 0.0, spin * OMEGA * t)
            disk.keyframe_insert("location", frame=frame)
            disk.keyframe_insert("rotation_euler", frame=frame)
        for fc in _common.fcurves(disk):
            for key in fc.keyframe_points:
                key.interpolation = 'LINEAR'
        p = disk.physanim.emitter
        p.enabled = True
        p.source, p.direction = 'VOLUME', 'RANDOM'
        p.rate, p.frame_start, p.frame_end = stars / 2, 1, 1
        p.speed, p.speed_random = 0.0, 0.15 * OMEGA * RADIUS  # a little random motion
        p.inherit_velocity = 1.0
        p.lifetime = 10.0 * FRAMES
        p.mass = mass
        p.size = 0.025
        p.seed = 3 + k
        p.render_as, p.glow_strength = 'GLOW', 1.5
        p.color_stops[0].color, p.color_stops[1].color = colours
    pull = bpy.data.objects.new("Gravity", None)
    scene.collection.objects.link(pull)
    f = pull.physanim.force
    f.enabled = True
    f.type = 'GRAVITY'
    f.gravity_constant = G
    f.softening = 0.25  # smooths the pull below this distance: no stars clumping in pairs
    f.theta = 0.7


def _stars(scene, frame: int) -> list[dict]:
    scene.frame_set(frame)
    return [_common.result_points(bpy.data.objects[f"Galaxy{k}"].physanim.emitter.result)
            for k in (1, 2)]


def check(scene) -> list[str]:
    problems = []
    first = _stars(scene, 1)
    d0 = np.linalg.norm(first[0]["position"].mean(0) - first[1]["position"].mean(0))
    closest = d0
    for frame in range(10, FRAMES + 1, 10):
        a, b = _stars(scene, frame)
        closest = min(closest, float(np.linalg.norm(a["position"].mean(0)
                                                    - b["position"].mean(0))))
    if closest > d0 / 3:
        problems.append(f"the disks came no closer than {closest:.2f} m (from {d0:.2f} m)")
    last = _stars(scene, FRAMES)

    def centre(disks):  # equal masses: the centre of mass and its velocity
        both = [np.concatenate([d[key] for d in disks]).astype(float).mean(axis=0)
                for key in ("position", "velocity")]
        return both[0], both[1]

    (c0, v0), (c1, _) = centre(first), centre(last)
    span = (FRAMES - 1) * scene.render.fps_base / scene.render.fps
    drift = float(np.linalg.norm(c1 - (c0 + v0 * span)))
    if drift > 0.01 * d0:
        problems.append(f"the centre of mass of all stars is {drift:.3f} m off the straight "
                        "line its starting momentum sets")
    x = np.concatenate([d["position"] for d in last]).astype(float)
    centres = [d["position"].mean(0) for d in last]
    far = np.min([np.linalg.norm(x - c, axis=1) for c in centres], axis=0) > 2 * RADIUS
    if far.mean() < 0.02:
        problems.append(f"only {100 * far.mean():.1f} % of the stars in tidal tails (farther "
                        f"than {2 * RADIUS:g} m from both centres)")
    if not math.isfinite(float(x.sum())):
        problems.append("a star's position is not finite")
    return problems
