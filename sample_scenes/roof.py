"""Logs and planks on a roof: a house with a gabled roof (one closed mesh ticked as a collider:
Automatic makes it a Mesh collider; its ridge is one sharp edge from gable to gable, with no
vertex between) takes logs and planks dropped across its ridge a little off the middle, every
one at the rigid-body defaults but its size. Each lands on the crest, pivots on it and comes
to rest on the crest and the slope its longer side leans to. Only the ridge's edge holds them
up where they cross it: the mesh's vertices are metres away at the gables, and a body's
corners are off the crest (before a mesh's edges met bodies, the crest went 2-9 cm into them
and they settled on their ends). Self-check: the ridge never reaches more than 1 cm into any
body in any frame, and every log and plank ends resting on it.
"""
from __future__ import annotations

import math

import numpy as np

from sample_scenes import _common

NAME = "roof"
LENGTH, HALF_WIDTH = 6.0, 2.0  # [m] the house along y, and from its middle to the eaves
EAVES, RIDGE = 1.5, 2.2  # [m] heights (slopes of 19 degrees)
DEPTH = 0.01  # [m] deepest the ridge may reach into a body
REST = 0.05  # [m/s] resting bodies move slower
ACROSS = (  # (kind, y along the ridge, offset from the ridge across it) of the long bodies
    ("Log", -2.2, 0.3), ("Plank", -1.1, -0.35), ("Log", 0.0, -0.25), ("Plank", 1.1, 0.3),
    ("Log", 2.2, 0.35))

# landing on the crest (16), pivoting onto the slopes (24), at rest (96)
SHOWCASE = (16, 24, 96)
README_FRAME = 24


def _house(bm) -> None:
    """A closed pentagonal prism along y, wound outward: walls to EAVES, a roof to RIDGE."""
    import bmesh

    outline = [(-HALF_WIDTH, 0.0), (HALF_WIDTH, 0.0), (HALF_WIDTH, EAVES), (0.0, RIDGE),
               (-HALF_WIDTH, EAVES)]
    front = [bm.verts.new((x, -LENGTH / 2, z)) for x, z in outline]
    back = [bm.verts.new((x, LENGTH / 2, z)) for x, z in outline]
    bm.faces.new(front)
    bm.faces.new(back[::-1])
    for i in range(5):
        j = (i + 1) % 5
        bm.faces.new((front[i], back[i], back[j], front[j]))
    bmesh.ops.recalc_face_normals(bm, faces=bm.faces[:])
    for face in bm.faces:  # the two roof slopes: tiles, a shade apart (the ridge shows)
        centre = face.calc_center_median()
        if centre.z > EAVES:
            face.material_index = 1 if centre.x < 0.0 else 2


def _long_body(scene, k: int, kind: str, y: float, offset: float, material):
    import bmesh

    if kind == "Log":
        def make(bm):  # a cylinder of 12 sides, its axis along x (across the ridge)
            bmesh.ops.create_cone(bm, cap_ends=True, segments=12, radius1=0.12, radius2=0.12,
                                  depth=2.2, matrix=_along_x())
    else:
        def make(bm):
            bmesh.ops.create_cube(bm, size=1.0)
            bmesh.ops.scale(bm, vec=(1.8, 0.3, 0.08), verts=bm.verts[:])
    ob = _common.add_mesh(scene, f"{kind}{k}", make)
    ob.location = (offset, y, RIDGE + 1.0 + 0.3 * k)
    ob.data.materials.append(material)
    ob.physanim.rigid_body.enabled = True
    return ob


def _along_x():
    from mathutils import Matrix

    return Matrix.Rotation(math.pi / 2, 4, 'Y')


def build(scene) -> None:
    _common.stage(scene, (2.5, -9.5, 3.2), (0.0, 0.0, 1.9), frame_end=96)
    _common.ground(scene)
    house = _common.add_mesh(scene, "House", _house)
    house.data.materials.append(_common.material("House", (0.8, 0.78, 0.72)))
    house.data.materials.append(_common.material("Tiles", (0.55, 0.2, 0.15)))
    house.data.materials.append(_common.material("Tiles lit", (0.75, 0.32, 0.22)))
    house.physanim.collider.enabled = True
    wood = (_common.material("Log", (0.45, 0.3, 0.17)), _common.material("Plank", (0.8, 0.6, 0.35)))
    for k, (kind, y, offset) in enumerate(ACROSS):
        _long_body(scene, k, kind, y, offset, wood[kind == "Plank"])


def _ridge_inside(ob) -> np.ndarray:
    """(points, faces): how far inside each face plane of the convex body ``ob`` (now) each
    point of the ridge (sampled every centimetre) is; a point is in the body where it is
    inside every plane."""
    verts = _common.evaluated_vertices(ob)
    tris = _common.triangles(ob)
    a, b, c = (verts[tris[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    ridge = np.stack([np.zeros(601), np.linspace(-LENGTH / 2, LENGTH / 2, 601),
                      np.full(601, RIDGE)], 1)
    return np.einsum("fi,fi->f", normal, a)[None] - ridge @ normal.T


def _ridge_depth(ob) -> float:
    """[m] how deep the ridge reaches into ``ob`` now (0 when it does not)."""
    return max(0.0, float(_ridge_inside(ob).min(axis=1).max()))


def _ridge_gap(ob) -> float:
    """[m] how far the ridge passes from ``ob`` now (0 when it touches or enters it)."""
    return max(0.0, float(-_ridge_inside(ob).min(axis=1).max()))


def check(scene) -> list[str]:
    problems = []
    end = scene.physanim.frame_end
    bodies = [o for o in scene.objects if o.physanim.rigid_body.enabled]
    deepest = {o.name: 0.0 for o in bodies}
    for frame in range(1, end + 1):
        scene.frame_set(frame)
        for ob in bodies:
            deepest[ob.name] = max(deepest[ob.name], _ridge_depth(ob))
    for name, depth in deepest.items():
        if depth > DEPTH:
            problems.append(f'the ridge reached {depth * 1000:.0f} mm into "{name}"')
    scene.frame_set(end - 1)
    before = {o.name: np.array(o.matrix_world.translation) for o in bodies}
    scene.frame_set(end)
    for ob in bodies:
        at = np.array(ob.matrix_world.translation)
        speed = np.linalg.norm(at - before[ob.name]) * scene.render.fps
        on = _ridge_gap(ob)
        if speed > REST or on > 0.02:
            problems.append(f'"{ob.name}" is not resting on the ridge ({speed:.2f} m/s, '
                            f"{on * 1000:.0f} mm off it)")
    return problems
