"""A pile in a bowl: 150 boxes, balls and convex-hull rocks, every one at the rigid-body
defaults but its size, pour into an open bowl (a Mesh collider: the lower half of a sphere's
mesh, Automatic) and heap up at its bottom. Self-check: every body ends inside the bowl (none
passes through its surface or sinks into it deeper than 2 cm), and the heap settles (at most a
tenth of the bodies still move at the end).
"""
from __future__ import annotations

import math

import numpy as np

from sample_scenes import _common

NAME = "bowl_pile"
RADIUS = 2.4  # [m] the bowl's
COUNT = 150
LAYER = 5  # bodies per row of the drop lattice (LAYER x LAYER per layer)
SPACING = 0.6  # [m] between drop positions
SINK = 0.02  # [m] deepest a body may end inside the bowl's surface
MOVING = 0.1  # fraction of the bodies allowed to move at the end

# pouring in (20), heaping (30), settled (96)
SHOWCASE = (20, 30, 96)
README_FRAME = 20


def _bowl(bm) -> None:
    """The lower half of a UV sphere of RADIUS centred at (0, 0, RADIUS): its bottom at the
    origin, open at the top (the equator)."""
    import bmesh

    bmesh.ops.create_uvsphere(bm, u_segments=48, v_segments=24, radius=RADIUS)
    upper = [v for v in bm.verts if v.co.z > 1e-6]
    bmesh.ops.delete(bm, geom=upper, context='VERTS')
    bmesh.ops.translate(bm, verts=bm.verts[:], vec=(0.0, 0.0, RADIUS))


def _body(scene, k: int, rng, materials):
    import bmesh

    kind = k % 3
    size = rng.uniform(0.22, 0.36)
    if kind == 0:
        def make(bm):
            bmesh.ops.create_cube(bm, size=size)
    elif kind == 1:
        def make(bm):
            bmesh.ops.create_icosphere(bm, subdivisions=2, radius=size * 0.6)
    else:
        lumps = rng.uniform(0.7, 1.15, 42)

        def make(bm):
            bmesh.ops.create_icosphere(bm, subdivisions=1, radius=size * 0.7)
            for v, f in zip(bm.verts, lumps):  # a lumpy rock
                v.co *= f
            bmesh.ops.convex_hull(bm, input=bm.verts[:])
    ob = _common.add_mesh(scene, f"Piece{k:03d}", make)
    layer, cell = divmod(k, LAYER * LAYER)
    i, j = divmod(cell, LAYER)
    ob.location = ((i - (LAYER - 1) / 2) * SPACING + rng.uniform(-0.05, 0.05),
                   (j - (LAYER - 1) / 2) * SPACING + rng.uniform(-0.05, 0.05),
                   RADIUS + 0.6 + layer * SPACING)
    ob.rotation_euler = tuple(rng.uniform(0.0, math.tau, 3))
    ob.data.materials.append(materials[kind])
    ob.physanim.rigid_body.enabled = True
    return ob


def build(scene) -> None:
    _common.stage(scene, (0.0, -8.5, 6.5), (0.0, 0.0, 1.2), frame_end=96)
    _common.ground(scene)
    bowl = _common.add_mesh(scene, "Bowl", _bowl)
    for poly in bowl.data.polygons:
        poly.use_smooth = True
    bowl.data.materials.append(_common.material("Bowl", (0.85, 0.85, 0.8)))
    bowl.physanim.collider.enabled = True
    materials = [_common.material("Crate", (0.75, 0.5, 0.25)),
                 _common.material("Ball", (0.2, 0.45, 0.8)),
                 _common.material("Stone", (0.45, 0.42, 0.38))]
    rng = np.random.default_rng(11)
    for k in range(COUNT):
        _body(scene, k, rng, materials)


def check(scene) -> list[str]:
    problems = []
    end = scene.physanim.frame_end
    pieces = [o for o in scene.objects if o.name.startswith("Piece")]
    scene.frame_set(end - 1)
    before = np.array([o.matrix_world.translation for o in pieces])
    scene.frame_set(end)
    centre = np.array([0.0, 0.0, RADIUS])
    moving = 0
    for ob, last in zip(pieces, before):
        verts = _common.evaluated_vertices(ob)
        below_rim = verts[:, 2] < RADIUS
        out = np.linalg.norm(verts[below_rim] - centre, axis=1) - RADIUS  # > 0: through it
        if len(out) and out.max() > SINK:
            problems.append(f'"{ob.name}" is {out.max() * 1000:.0f} mm into or through the bowl')
        if np.linalg.norm(np.array(ob.matrix_world.translation) - centre) > RADIUS:
            problems.append(f'"{ob.name}" ended outside the bowl')
        speed = np.linalg.norm(np.array(ob.matrix_world.translation) - last) * scene.render.fps
        moving += speed > 0.01
    if moving > MOVING * len(pieces):
        problems.append(f"{moving} of {len(pieces)} bodies still move at frame {end}")
    return problems
