"""Jelly cube: a soft cube drops on the ground and a hammer squashes it. Edge springs alone let
it fold inside out; with shear and angular springs it springs back (self-check: its signed
volume stays positive and recovers)."""
from __future__ import annotations

import bpy
import numpy as np

from sample_scenes import _common

NAME = "jelly_cube"
SIZE = 1.0


# Frames that show the point (the hammer squashing it, frames 46-52; its bulge as the hammer
# lifts; springing back); README_FRAME is the README's picture.
SHOWCASE = (47, 55, 70)
README_FRAME = 55

def build(scene, shear: bool = True, angular: bool = True) -> None:
    import bmesh

    _common.stage(scene, (4.2, -5.0, 1.6), (0.0, 0.0, 0.5), frame_end=120)
    _common.ground(scene)

    def make(bm):
        bmesh.ops.create_cube(bm, size=SIZE)
        bmesh.ops.subdivide_edges(bm, edges=bm.edges[:], cuts=4, use_grid_fill=True)
    jelly = _common.add_mesh(scene, "Jelly", make)
    jelly.location = (0.0, 0.0, 1.2)
    jelly.data.materials.append(_common.material("Jelly", (0.35, 0.85, 0.3)))
    for poly in jelly.data.polygons:
        poly.use_smooth = True
    p = jelly.physanim.spring_mesh
    p.enabled = True
    p.mass = 2.0
    p.stiffness, p.damping = 400.0, 0.5
    p.shear_stiffness, p.shear_damping = (400.0, 0.5) if shear else (0.0, 0.0)
    p.bend_mode = 'ANGULAR' if angular else 'NONE'
    p.bend_stiffness, p.bend_damping = 2.0, 0.02
    p.drag = 0.2
    hammer = _common.add_mesh(scene, "Hammer", lambda bm: bmesh.ops.create_cube(bm, size=2.0))
    hammer.scale = (1.2, 1.2, 0.25)
    hammer.data.materials.append(_common.material("Hammer", (0.35, 0.35, 0.4)))
    for frame, z in ((1, 4.0), (40, 4.0), (46, 0.55), (52, 0.55), (64, 4.0)):
        hammer.location = (0.0, 0.0, z)
        hammer.keyframe_insert("location", index=2, frame=frame)
    c = hammer.physanim.collider
    c.enabled, c.shape, c.restitution, c.friction = True, 'BOX', 0.0, 0.5
    g = scene.objects["Ground"].physanim.collider
    g.restitution, g.friction = 0.2, 0.8
    scene.physanim.integrator = 'IMPLICIT'
    scene.physanim.spring_substeps = 4


def volumes(scene, frames) -> np.ndarray:
    jelly = bpy.data.objects["Jelly"]
    tris = _common.triangles(jelly)
    out = []
    for frame in frames:
        scene.frame_set(frame)
        out.append(_common.signed_volume(_common.evaluated_vertices(jelly), tris))
    return np.array(out)


def check(scene) -> list[str]:
    problems = []
    frames = list(range(1, scene.physanim.frame_end + 1, 3))
    vol = volumes(scene, frames)
    start = vol[0]
    if vol.min() <= 0.0:
        problems.append(f"the cube turned inside out (signed volume {vol.min():.3f} m^3 at "
                        f"frame {frames[int(np.argmin(vol))]})")
    squashed = vol[(np.array(frames) >= 46) & (np.array(frames) <= 52)]
    if squashed.max() > 0.8 * start:
        problems.append("the hammer did not squash the cube")
    if vol[-1] < 0.75 * start:
        problems.append(f"the cube did not recover: {vol[-1] / start:.0%} of its volume at the end")
    return problems
