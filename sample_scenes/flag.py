"""Flag: a cloth grid pinned along the pole flaps in a gusty wind, never folding through
itself (self-collision)."""
from __future__ import annotations

import math

import bpy
import numpy as np

from sample_scenes import _common

NAME = "flag"
WIDTH, HEIGHT = 3.0, 2.0
POLE_X = -WIDTH / 2


# Frames that show the point (the flag streaming and flapping in the gusts); README_FRAME is the
# README's picture.
SHOWCASE = (40, 80, 120)
README_FRAME = 80

def build(scene) -> None:
    import bmesh

    _common.stage(scene, (1.5, -9.0, 3.2), (0.3, 0.0, 3.4), frame_end=120)
    _common.ground(scene, color=(0.25, 0.35, 0.2))
    pole = _common.add_mesh(scene, "Pole", lambda bm: bmesh.ops.create_cone(
        bm, cap_ends=True, segments=16, radius1=0.05, radius2=0.05, depth=5.0))
    pole.location = (POLE_X - 0.05, 0.0, 2.5)
    pole.data.materials.append(_common.material("Pole", (0.7, 0.7, 0.72)))
    flag = _common.grid(scene, "Flag", 30, 20, WIDTH)
    flag.rotation_euler = (math.radians(90.0), 0.0, 0.0)  # hang in the XZ plane
    flag.location = (0.0, 0.0, 5.0 - HEIGHT / 2)
    flag.data.materials.append(_common.material("Flag", (0.85, 0.12, 0.1)))
    for poly in flag.data.polygons:
        poly.use_smooth = True
    co = np.array([v.co[:] for v in flag.data.vertices])
    pinned = [int(i) for i in np.nonzero(co[:, 0] < co[:, 0].min() + 1e-6)[0]]
    group = flag.vertex_groups.new(name="Pole")
    group.add(pinned, 1.0, 'REPLACE')
    p = flag.physanim.spring_mesh
    p.enabled = True
    p.mass = 0.4
    p.stiffness, p.damping = 400.0, 0.05
    p.shear_stiffness, p.shear_damping = 40.0, 0.01
    p.bend_mode, p.bend_stiffness, p.bend_damping = 'ANGULAR', 5e-4, 1e-5
    p.drag = 0.4
    p.pin_group = "Pole"
    p.self_collision = True  # its folds lie on each other instead of passing through
    wind = bpy.data.objects.new("Wind", None)
    wind.empty_display_type = 'SINGLE_ARROW'
    wind.rotation_euler = (0.0, math.radians(90.0), math.radians(10.0))  # local Z -> +X, a bit +Y
    wind.location = (POLE_X - 1.0, 0.0, 4.0)
    scene.collection.objects.link(wind)
    f = wind.physanim.force
    f.enabled = True
    f.type = 'WIND'
    f.strength = 12.0  # N/m^2 (about a 4.5 m/s breeze: 0.5 rho v^2)
    f.noise, f.noise_scale, f.noise_speed = 0.8, 1.5, 0.8
    scene.physanim.integrator = 'IMPLICIT'
    scene.physanim.spring_substeps = 2


def check(scene) -> list[str]:
    problems = []
    flag = bpy.data.objects["Flag"]
    group = flag.vertex_groups["Pole"].index
    pinned = np.array([v.index for v in flag.data.vertices
                       if any(g.group == group for g in v.groups)])
    scene.frame_set(1)
    rest = _common.evaluated_vertices(flag)
    edges = np.array([e.vertices[:] for e in flag.data.edges])
    rest_len = np.linalg.norm(rest[edges[:, 0]] - rest[edges[:, 1]], axis=1)
    flag.data.calc_loop_triangles()
    tris = [t.vertices[:] for t in flag.data.loop_triangles]
    samples = []
    for frame in range(30, scene.physanim.frame_end + 1, 10):
        scene.frame_set(frame)
        x = _common.evaluated_vertices(flag)
        if not np.all(np.isfinite(x)):
            problems.append(f"frame {frame}: non-finite vertices")
            return problems
        if np.abs(x[pinned] - rest[pinned]).max() > 1e-4:
            problems.append(f"frame {frame}: the flag came off the pole")
        strain = np.linalg.norm(x[edges[:, 0]] - x[edges[:, 1]], axis=1) / rest_len - 1.0
        if np.percentile(strain, 99) > 0.2 or strain.max() > 1.0:
            problems.append(f"frame {frame}: the cloth stretched by {strain.max():.0%} "
                            f"(99th percentile {np.percentile(strain, 99):.0%})")
        crossed = _common.crossings(x, tris)
        if crossed:
            problems.append(f"frame {frame}: the flag passes through itself ({crossed} "
                            "triangle pairs overlap)")
        samples.append(x)
    samples = np.array(samples)
    free_end = samples[:, ~np.isin(np.arange(len(rest)), pinned)]
    if free_end[:, :, 0].mean() < POLE_X + 0.3 * WIDTH:  # flying out: mean at the middle
        problems.append("the wind does not blow the flag out from the pole")
    if free_end.std(axis=0).mean() < 0.02:
        problems.append("the flag does not flap: it hardly moves between frames")
    return problems

