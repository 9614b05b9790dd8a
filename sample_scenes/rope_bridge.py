"""Rope bridge: two ropes slung between posts carry twelve wooden planks. A gust has just
struck it: the planks start with a sideways speed, most in the middle, so the bridge swings out
and back, bobs as it drops into the sag its planks' weight gives the ropes, and settles. The
ropes are one spring mesh (two lines of vertices 10 cm apart, pinned at the posts); each plank
is a rigid body held on the rope vertices under it by a constraint (an Empty, as Connect
Selected makes them). Ropes and planks move each other both ways: the planks' weight pulls the
ropes down and the ropes swing and turn the planks. The rope's Skin modifier (drawing it as a
rope) comes after the bake's Mesh Cache modifier, which the scene adds first in the stack so
that the bake plays its result into the Skin rather than baking the skinned tube.

Self-check: every plank stays on the ropes (the vertices held on it within 5 mm of where they
were bound, in the plank's frame, in every frame), no rope segment stretches by more than 5 %,
the middle of the deck swings out at least 10 cm and comes back within 3 cm, it sags under the
planks, and the bridge is at rest at the end (no plank faster than 5 cm/s).
"""
from __future__ import annotations

import math

import bpy
import numpy as np
from mathutils import Matrix, Vector

from sample_scenes import _common

NAME = "rope_bridge"
FRAMES = 120
SPAN = 4.4  # [m] between the posts
TOP = 2.0  # [m] the ropes' ends
SAG = 0.3  # [m] how far the ropes hang below their ends at the middle, as built
GAUGE = 0.9  # [m] between the two ropes
SEGMENT = 0.1  # [m] the ropes' vertex spacing (about)
PLANKS = 12
PLANK = (0.3, 1.1, 0.04)  # [m] along the bridge, across, thick
PLANK_MASS = 2.0  # [kg]
ROPE_MASS = 2.0  # [kg] both ropes
ROPE_STIFFNESS = 100_000.0  # [N/m] per segment
GUST = 1.2  # [m/s] the middle planks' sideways speed at the start
ON_PLANK = 0.005  # [m]
STRETCH = 0.05
SWING, BACK = 0.10, 0.03  # [m]
SETTLED = 0.05  # [m/s]

# struck (1), swung out (8), swinging back (20), settled (120)
SHOWCASE = (1, 8, 20, 120)
README_FRAME = 8


def _rope_z(x: np.ndarray) -> np.ndarray:
    """The ropes' height as built: a parabola through both posts, SAG below them mid-span."""
    return TOP - SAG * (1.0 - (2.0 * x / SPAN) ** 2)


def _planks() -> list[str]:
    return [f"Plank{i:02d}" for i in range(PLANKS)]


def _plank_x() -> np.ndarray:
    """The planks' centres along the bridge (evenly over the middle 90 % of the span)."""
    reach = 0.45 * SPAN - PLANK[0] / 2
    return np.linspace(-reach, reach, PLANKS)


def build(scene) -> None:
    import bmesh

    _common.stage(scene, (3.2, -7.6, 3.0), (0.0, 0.0, 1.3), frame_end=FRAMES)
    _common.ground(scene)
    wood = _common.material("Wood", (0.5, 0.33, 0.18))
    dark = _common.material("Post", (0.3, 0.2, 0.12))

    cuts = int(round(SPAN / SEGMENT))
    x = np.linspace(-SPAN / 2, SPAN / 2, cuts + 1)
    z = _rope_z(x)

    def ropes(bm) -> None:
        for y in (-GAUGE / 2, GAUGE / 2):
            verts = [bm.verts.new((xi, y, zi)) for xi, zi in zip(x, z)]
            for a, b in zip(verts, verts[1:]):
                bm.edges.new((a, b))

    rope = _common.add_mesh(scene, "Ropes", ropes)
    # drawn as a thick rope: a Skin modifier after the bake's Mesh Cache (made here, first in
    # the stack, so the bake plays its result into the Skin rather than baking the skinned tube)
    rope.modifiers.new("physanim", 'MESH_CACHE')
    rope.modifiers.new("Skin", 'SKIN')
    for v in rope.data.skin_vertices[0].data:
        v.radius = (0.02, 0.02)
    rope.data.materials.append(_common.material("Rope", (0.75, 0.65, 0.42)))
    ends = rope.vertex_groups.new(name="Posts")
    ends.add([0, cuts, cuts + 1, 2 * cuts + 1], 1.0, 'REPLACE')
    p = rope.physanim.spring_mesh
    p.enabled, p.mass, p.stiffness, p.pin_group = True, ROPE_MASS, ROPE_STIFFNESS, "Posts"

    for sx in (-1.0, 1.0):
        for y in (-GAUGE / 2, GAUGE / 2):
            post = _common.add_mesh(scene, "Post", lambda bm: bmesh.ops.create_cube(
                bm, size=1.0, matrix=Matrix.Diagonal((0.12, 0.12, TOP + 0.2, 1.0))))
            post.location = (sx * (SPAN / 2 + 0.08), y, (TOP + 0.2) / 2)
            post.data.materials.append(dark)

    for name, cx in zip(_planks(), _plank_x()):
        slope = math.atan(SAG * 8.0 * cx / SPAN ** 2)  # the ropes' slope there
        plank = _common.add_mesh(scene, name, lambda bm: bmesh.ops.create_cube(
            bm, size=1.0, matrix=Matrix.Diagonal((*PLANK, 1.0))))
        up = np.array([-math.sin(slope), 0.0, math.cos(slope)])
        centre = np.array([cx, 0.0, _rope_z(np.array(cx))]) + up * (PLANK[2] / 2 + 0.02)
        plank.matrix_world = Matrix.Translation(Vector(centre)) @ Matrix.Rotation(-slope, 4, 'Y')
        plank.data.materials.append(wood)
        r = plank.physanim.rigid_body
        r.enabled, r.mass = True, PLANK_MASS
        r.initial_velocity = (0.0, GUST * math.cos(math.pi * cx / SPAN), 0.0)
        under = np.nonzero(np.abs(x - cx) <= PLANK[0] / 2)[0]
        group = rope.vertex_groups.new(name=name)
        group.add([int(i) for i in under] + [int(i) + cuts + 1 for i in under], 1.0, 'REPLACE')
        hold = bpy.data.objects.new(f"Hold{name[5:]}", None)
        hold.empty_display_size = 0.1
        hold.location = Vector(centre)
        scene.collection.objects.link(hold)
        c = hold.physanim.constraint
        c.enabled, c.object1, c.group1, c.object2 = True, rope, name, plank



def _rope(scene, rope) -> np.ndarray:
    """(frames, n, 3) the ropes' vertices (the baked cache, the Skin modifier off)."""
    skin = rope.modifiers["Skin"]
    skin.show_viewport = False
    try:
        out = []
        for f in range(1, FRAMES + 1):
            scene.frame_set(f)
            out.append(_common.evaluated_vertices(rope))
        return np.array(out)
    finally:
        skin.show_viewport = True


def check(scene) -> list[str]:
    problems = []
    rope = bpy.data.objects["Ropes"]
    x = _rope(scene, rope)
    m = _common.track(scene, _planks(), range(1, FRAMES + 1))
    if not np.all(np.isfinite(x)):
        return ["the ropes have non-finite vertices"]
    off = 0.0
    for k, name in enumerate(_planks()):
        index = np.array([v.index for v in rope.data.vertices
                          if any(g.group == rope.vertex_groups[name].index for g in v.groups)])
        inv = np.linalg.inv(m[:, k])
        local = np.einsum("fij,fkj->fki", inv[:, :3, :3], x[:, index]) + inv[:, None, :3, 3]
        off = max(off, float(np.linalg.norm(local - local[0], axis=2).max()))
    if off > ON_PLANK:
        problems.append(f"a plank came off the ropes ({off * 1000:.1f} mm)")
    edges = np.array([e.vertices[:] for e in rope.data.edges])
    built = np.array([v.co[:] for v in rope.data.vertices])
    rest = np.linalg.norm(built[edges[:, 0]] - built[edges[:, 1]], axis=1)
    length = np.linalg.norm(x[:, edges[:, 0]] - x[:, edges[:, 1]], axis=2)
    stretch = float((length / rest).max() - 1.0)
    if stretch > STRETCH:
        problems.append(f"a rope segment stretched by {stretch:.1%}")
    middle = m[:, PLANKS // 2, :3, 3]
    out, back = np.abs(middle[:, 1]).max(), abs(middle[-1, 1])
    if out < SWING:
        problems.append(f"the deck swung out only {out * 100:.1f} cm")
    if back > BACK:
        problems.append(f"the deck did not swing back ({back * 100:.1f} cm out at the end)")
    if middle[-1, 2] > middle[0, 2] - 0.02:
        problems.append("the deck did not sag under its planks")
    speed = np.linalg.norm(np.diff(m[-6:, :, :3, 3], axis=0), axis=2).max() * scene.render.fps
    if speed > SETTLED:
        problems.append(f"the bridge is still moving at the end ({speed:.2f} m/s)")
    return problems
