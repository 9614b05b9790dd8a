"""A new user's first bake: tag an object in a role, change nothing else, bake, and get something
physically sensible. Every role object here is a Blender primitive with only ``enabled`` set on
the role under test (scene, camera-like aiming of a helper emitter and primitive sizes are set
up as a user would place objects; the role's own properties keep their defaults)."""
from __future__ import annotations

import math
import re
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest
from mathutils import Vector
from mathutils.bvhtree import BVHTree


def _core(ext, name: str):
    return sys.modules[f"{ext.__name__}.core.{name}"]


def _save(tmp_path: Path) -> None:
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "first.blend"))


def _frames(ext, ob) -> dict[int, dict[str, np.ndarray]]:
    """Every cached frame of an emitter's result."""
    res = ob.physanim.emitter.result
    folder = bpy.path.abspath(res.physanim.result.cache)
    scene = bpy.context.scene
    read = _core(ext, "cache").read_frame
    return {f: read(folder, f) for f in range(scene.physanim.frame_start,
                                                scene.physanim.frame_end + 1)}


def _pc2(ext, ob) -> np.ndarray:
    """(frames, n, 3) world positions of a baked spring mesh (object-space cache mapped)."""
    path = bpy.path.abspath(ob.modifiers["physanim"].filepath)
    samples = _core(ext, "pc2").read_pc2(path)[0]
    m = np.array(ob.matrix_world)
    return samples @ m[:3, :3].T + m[:3, 3]


def _primitive(kind: str, **kw) -> bpy.types.Object:
    getattr(bpy.ops.mesh, f"primitive_{kind}_add")(**kw)
    return bpy.context.object


# ------------------------------------------------------------------------------- emitter

@pytest.mark.parametrize("kind", ["plane", "cube", "monkey"])
def test_emitter_at_its_defaults(physanim_ext, tmp_path, kind):
    ob = _primitive(kind)
    ob.physanim.emitter.enabled = True
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    p = ob.physanim.emitter
    frames = _frames(physanim_ext, ob)
    seen = set()
    for f, a in frames.items():
        ids = set(a["id"].tolist())
        assert len(ids) == len(a["id"]), f"frame {f}: ids repeat"
        born = ids - seen
        expected = p.rate if p.frame_start <= f <= p.frame_end else 0  # no randomness by default
        assert len(born) == expected, (f, len(born))
        seen |= ids
        assert np.isfinite(a["position"]).all() and np.isfinite(a["velocity"]).all()
    # a steady state: 50 frames of births alive at once (the default life span)
    assert abs(len(frames[120]["id"]) - p.rate * p.lifetime) <= p.rate
    # births stop at frame 200, every life span is 50 frames: all dead by the last frame, 250
    assert p.frame_end + p.lifetime <= 250 and len(frames[250]["id"]) == 0
    # newborns leave the surface at the default speed, then fall: gravity acts
    young = frames[100]["age"] <= 1.0
    speed = np.linalg.norm(frames[100]["velocity"][young], axis=1)
    assert np.all(np.abs(speed - p.speed) < 9.81 / 24 + 1e-3)
    old = frames[100]["age"] > 40
    assert np.all(frames[100]["velocity"][old][:, 2] < frames[100]["velocity"][young][:, 2].min())


def test_emission_window_includes_its_last_frame(physanim_ext, tmp_path):
    scene = bpy.context.scene
    scene.physanim.frame_end = 30
    burst = bpy.data.objects.new("Burst", None)
    scene.collection.objects.link(burst)
    burst.physanim.emitter.enabled = True
    burst.physanim.emitter.frame_start = burst.physanim.emitter.frame_end = 1
    burst.physanim.emitter.rate = 1.0
    stream = bpy.data.objects.new("Stream", None)
    scene.collection.objects.link(stream)
    stream.physanim.emitter.enabled = True
    stream.physanim.emitter.frame_end = 24
    stream.physanim.emitter.rate = 40.0
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    one = _frames(physanim_ext, burst)
    assert len(one[1]["id"]) == 1  # the one-frame burst shows at frame 1
    only = set(one[1]["id"].tolist())
    assert all(set(a["id"].tolist()) <= only for a in one.values())  # and nothing after it
    many = _frames(physanim_ext, stream)
    ids = set().union(*(set(a["id"].tolist()) for a in many.values()))
    assert len(ids) == 40 * 24  # rate x (end - start + 1)
    assert len(many[24]["id"]) == 40 * 24  # all born by frame 24, none dead yet


# ------------------------------------------------------------------------------ collider

def _gun(target: Vector, scene) -> bpy.types.Object:
    """An emitter 4 m in front of ``target`` firing at it at 100 m/s (frames 1-10)."""
    gun = bpy.data.objects.new("Gun", None)
    scene.collection.objects.link(gun)
    gun.location = target + Vector((0.0, -4.0, 0.0))
    gun.rotation_euler = (-math.pi / 2, 0.0, 0.0)  # local +Z -> world +Y
    p = gun.physanim.emitter
    p.enabled = True
    p.speed, p.spread, p.rate, p.frame_end, p.lifetime = 100.0, 0.35, 30.0, 10, 200.0
    return gun


COLLIDERS = {
    "plane": dict(rotation=(math.pi / 2 - 0.3, 0.0, 0.0)),
    "cube": dict(rotation=(0.3, 0.2, 0.1)),
    "ico_sphere": dict(),
    "grid": dict(x_subdivisions=12, y_subdivisions=12, rotation=(math.pi / 2 - 0.4, 0.0, 0.2)),
    "monkey": dict(rotation=(0.0, 0.0, math.pi)),
}


@pytest.mark.parametrize("kind", list(COLLIDERS))
def test_collider_at_its_defaults_stops_particles_at_its_visible_surface(physanim_ext, tmp_path,
                                                                         kind):
    scene = bpy.context.scene
    scene.physanim.frame_end = 24
    scene.use_gravity = False  # straight shots: any particle behind the surface went through it
    target = _primitive(kind, **COLLIDERS[kind])
    target.physanim.collider.enabled = True
    gun = _gun(Vector((0.0, 0.0, 0.0)), scene)
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    bvh = BVHTree.FromObject(target, bpy.context.evaluated_depsgraph_get())
    inv = target.matrix_world.inverted()
    origin = inv @ gun.matrix_world.translation
    through = 0
    for a in _frames(physanim_ext, gun).values():
        for q in a["position"]:
            local = inv @ Vector(q.tolist())
            ray = local - origin
            hit = bvh.ray_cast(origin, ray.normalized(), ray.length)[0]
            if hit is None:
                continue  # nothing between the gun and this particle: it missed or bounced back
            # the surface lies between the gun and the particle: it got through, unless it is
            # still on the gun's side of the surface nearest to it (it bounced off a ridge)
            near, normal = bvh.find_nearest(local)[:2]
            through += (local - near).dot(normal) < -1e-4
    assert through == 0
    # and the shots did reach it: a good part of them bounced back towards the gun
    last = _frames(physanim_ext, gun)[24]
    assert len(last["id"]) == 300 and (last["velocity"][:, 1] < 0.0).sum() > 30
    # and only what is there stops them: shots beside the object fly on past it
    assert (last["position"][:, 1] > 5.0).sum() > 10


def test_rain_at_its_defaults_bounces_on_a_mesh_collider_at_its_defaults(physanim_ext,
                                                                          tmp_path):
    # a wide cylinder (an Automatic collider: a Mesh) under a default emitter: the particles
    # (shot up at the default 5 m/s) fall on its top and bounce there until they die, and no
    # particle is ever behind its visible surface (a still Mesh collider answers its particles
    # near the surface through its triangle grid)
    scene = bpy.context.scene
    scene.physanim.frame_end = 72
    post = _primitive("cylinder", radius=4.0)  # z from -1 to 1: the top at 1
    post.physanim.collider.enabled = True
    extract = sys.modules[f"{physanim_ext.__name__}.addon.extract"]
    assert extract.automatic_collider(post)[0] == 'MESH'
    rain = _primitive("plane", size=1.2, location=(0.0, 0.0, 2.0))
    rain.physanim.emitter.enabled = True
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    bvh = BVHTree.FromObject(post, bpy.context.evaluated_depsgraph_get())
    touching = 0
    for f, a in _frames(physanim_ext, rain).items():
        for i, q in enumerate(a["position"]):
            near, normal, _, dist = bvh.find_nearest(Vector(q.tolist()))
            side = (Vector(q.tolist()) - near).dot(normal)
            if abs(abs(side) - dist) < 1e-6:  # nearest to a face's inside: the side is sure
                assert side > -1e-4, (f, i, dist)
        assert (a["position"][:, 2] > 1.0 - 1e-4).all(), f  # all on or over the top
        touching += int((a["position"][:, 2] < 1.01).sum())
    assert touching > 100  # the rain reached the top and bounced there


# --------------------------------------------------------------------------- spring mesh

@pytest.mark.parametrize("kind", ["grid", "cube", "monkey"])
def test_spring_mesh_at_its_defaults_falls_lands_and_rests(physanim_ext, tmp_path, kind):
    scene = bpy.context.scene
    ground = _primitive("plane", size=20.0)
    ground.physanim.collider.enabled = True
    ob = _primitive(kind, location=(0.0, 0.0, 2.0))
    ob.physanim.spring_mesh.enabled = True
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert scene.physanim.bake_info.startswith("baked 1 spring mesh, frames")  # no emitters
    x = _pc2(physanim_ext, ob)
    assert x.shape[0] == scene.physanim.frame_end - scene.physanim.frame_start + 1
    assert np.isfinite(x).all()
    z = x[..., 2]
    assert z[0].min() > 0.9  # starts in the air
    assert z.min() > -2e-3, "a vertex went through the ground"
    assert z[-1].min() < 0.02, "it never landed"
    speed = np.linalg.norm(x[-1] - x[-2], axis=1) * 24.0
    assert speed.max() < 0.05, f"not at rest after {x.shape[0]} frames ({speed.max():.3f} m/s)"
    # at rest it sleeps (Sleep When Still, on by default): its last 100 frames are the same
    # to the bit (the monkey, a closed mesh, held its springs' micrometre jitter without it)
    moved = [f for f in range(1, len(x)) if not np.array_equal(x[f], x[f - 1])]
    assert moved[-1] < len(x) - 100, f"still moving at frame {moved[-1] + 1}"
    # and the bake's summary says from which frame: at most half a second after the cache
    # stopped changing (static friction can hold a flat cloth exactly before it sleeps)
    still = scene.physanim.frame_start + moved[-1]
    asleep = re.search(f'"{ob.name}" at rest \\(asleep\\) from frame (\\d+)',
                       scene.physanim.bake_info)
    assert asleep is not None, scene.physanim.bake_info
    assert still <= int(asleep.group(1)) <= still + 13
    size0 = np.ptp(x[0], axis=0).max()
    assert 0.5 * size0 < np.ptp(x[-1], axis=0).max() < 1.5 * size0  # it kept its shape


@pytest.mark.parametrize("kind", ["cube", "ico_sphere"])
def test_spring_mesh_draped_on_a_default_collider_stays_outside(physanim_ext, tmp_path, kind):
    scene = bpy.context.scene
    scene.physanim.frame_end = 60
    target = _primitive(kind, size=1.0) if kind == "cube" else _primitive(kind, radius=0.5)
    target.physanim.collider.enabled = True
    cloth = _primitive("grid", x_subdivisions=16, y_subdivisions=16, size=2.0,
                       location=(0.1, 0.0, 1.0))
    cloth.physanim.spring_mesh.enabled = True
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    bvh = BVHTree.FromObject(target, bpy.context.evaluated_depsgraph_get())
    inv = target.matrix_world.inverted()
    x = _pc2(physanim_ext, cloth)
    for f in range(0, len(x), 5):
        for q in x[f]:
            local = inv @ Vector(q.tolist())
            near, normal = bvh.find_nearest(local)[:2]
            assert (local - near).dot(normal) > -2e-3, f"frame {f + 1}: a vertex is inside"
    assert x[-1][:, 2].max() > 0.4  # it hangs over the collider instead of falling through


@pytest.mark.parametrize("kind", ["uv_sphere", "cone"])
def test_default_cube_dropped_on_a_default_sphere_or_cone_never_has_it_inside(physanim_ext,
                                                                              tmp_path, kind):
    """The issue's first report: the default cube as a spring mesh (8 vertices) fell straight
    through a default sphere collider, which passed between its vertices. Dropped on the
    default UV sphere or cone (its tip), the collider's visible triangles never overlap the
    cube's at any frame (Blender's own BVH overlap test), and the cube is caught: half a
    second after its bottom reaches the collider's top it still reaches above it (falling
    through it would be 2 m lower)."""
    scene = bpy.context.scene
    scene.physanim.frame_end = 72
    target = _primitive(kind)
    target.physanim.collider.enabled = True
    cube = _primitive("cube", location=(0.0, 0.0, 3.5))
    cube.physanim.spring_mesh.enabled = True
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    mw = target.matrix_world
    target.data.calc_loop_triangles()
    ours = BVHTree.FromPolygons([mw @ v.co for v in target.data.vertices],
                                [t.vertices[:] for t in target.data.loop_triangles])
    cube.data.calc_loop_triangles()  # the triangles the simulation and the viewport use
    polygons = [t.vertices[:] for t in cube.data.loop_triangles]
    top = max((mw @ v.co).z for v in target.data.vertices)
    x = _pc2(physanim_ext, cube)
    touched = None
    for f, q in enumerate(x):
        theirs = BVHTree.FromPolygons([Vector(p.tolist()) for p in q], polygons)
        assert not theirs.overlap(ours), f"frame {f + 1}: the {kind} is inside the cube"
        if touched is None and q[:, 2].min() < top:
            touched = f
    assert touched is not None
    assert x[touched + 12][:, 2].max() > top, "the cube fell past the collider"


def _self_crossings(co: np.ndarray, tris: list) -> int:
    """Overlapping triangle pairs of one mesh that share no vertex (Blender's BVH overlap)."""
    tree = BVHTree.FromPolygons([Vector(p.tolist()) for p in co], tris)
    return sum(1 for a, b in tree.overlap(tree) if a < b and not set(tris[a]) & set(tris[b]))


@pytest.mark.parametrize("on", [False, True])
def test_self_collision_alone_keeps_a_folding_grid_from_crossing_itself(physanim_ext, tmp_path,
                                                                         on):
    """A grid standing on edge falls onto the ground and folds over onto itself. With only
    Self Collision switched on, no two of its triangles that share no vertex overlap at any
    frame (Blender's own BVH overlap test on the viewport's triangles); without it, the same
    drop folds through itself."""
    scene = bpy.context.scene
    scene.physanim.frame_end = 48
    ground = _primitive("plane", size=10.0)
    ground.physanim.collider.enabled = True
    sheet = _primitive("grid", x_subdivisions=14, y_subdivisions=14, size=1.0,
                       location=(0.0, 0.0, 0.8), rotation=(math.radians(87.0), 0.0, 0.0))
    sheet.physanim.spring_mesh.enabled = True
    sheet.physanim.spring_mesh.self_collision = on
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    sheet.data.calc_loop_triangles()
    tris = [t.vertices[:] for t in sheet.data.loop_triangles]
    worst = max(_self_crossings(q, tris) for q in _pc2(physanim_ext, sheet))
    assert (worst == 0) if on else (worst > 10), worst


# --------------------------------------------------------------------------------- forces

FORCES = ["WIND", "DRAG", "ATTRACTOR", "VORTEX"]


def _force_scene(kind: str | None):
    scene = bpy.context.scene
    scene.physanim.frame_end = 30
    scene.use_gravity = False
    emitter = bpy.data.objects.new("Spray", None)
    scene.collection.objects.link(emitter)
    emitter.physanim.emitter.enabled = True
    cloth = _primitive("grid", x_subdivisions=6, y_subdivisions=6, size=1.0,
                       location=(0.0, 2.0, 1.0))
    cloth.physanim.spring_mesh.enabled = True
    if kind is not None:
        field = bpy.data.objects.new("Field", None)
        scene.collection.objects.link(field)
        field.location = (1.0, 1.0, 0.0)
        field.physanim.force.enabled = True
        field.physanim.force.type = kind
    return emitter, cloth


@pytest.mark.parametrize("kind", FORCES)
def test_every_force_at_its_defaults_moves_particles_and_spring_meshes(physanim_ext, tmp_path, kind):
    results = []
    for with_force in (False, True):
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        emitter, cloth = _force_scene(kind if with_force else None)
        _save(tmp_path)
        assert bpy.ops.physanim.bake() == {'FINISHED'}
        a = _frames(physanim_ext, emitter)[30]
        results.append((a["id"], a["position"], a["velocity"], _pc2(physanim_ext, cloth)[-1]))
    (ids0, x0, v0, c0), (ids1, x1, v1, c1) = results
    np.testing.assert_array_equal(ids0, ids1)  # the same particles (same seed), moved otherwise
    centre = np.array([1.0, 1.0, 0.0])
    if kind == "WIND":  # along the force object's local +Z
        assert (x1[:, 2] - x0[:, 2]).mean() > 0.01 and (c1[:, 2] - c0[:, 2]).mean() > 1e-4
    elif kind == "DRAG":
        assert np.linalg.norm(v1, axis=1).mean() < 0.99 * np.linalg.norm(v0, axis=1).mean()
        # the cloth is at rest without gravity: drag leaves it alone, as it should
        np.testing.assert_allclose(c1, c0, atol=1e-9)
    elif kind == "ATTRACTOR":
        def dist(p):
            return np.linalg.norm(p - centre, axis=1).mean()
        assert dist(x1) < dist(x0) - 1e-3 and dist(c1) < dist(c0) - 1e-4
    else:  # VORTEX about the local Z axis through the object: a turn, not a push along z
        def angle(p):
            return np.arctan2(p[:, 1] - centre[1], p[:, 0] - centre[0])
        turn = np.angle(np.exp(1j * (angle(x1) - angle(x0))))
        cloth_turn = np.angle(np.exp(1j * (angle(c1) - angle(c0))))
        assert turn.mean() > 1e-3 and cloth_turn.mean() > 1e-5
        np.testing.assert_allclose(c1[:, 2], c0[:, 2], atol=1e-6)


def test_automatic_collider_shape_is_what_the_mesh_is(physanim_ext):
    extract = sys.modules[f"{physanim_ext.__name__}.addon.extract"]

    def shape(ob):
        return extract.automatic_collider(ob)[0]

    assert shape(_primitive("plane", size=3.0, rotation=(0.4, 0.0, 0.0))) == 'PLANE'
    assert shape(_primitive("grid", x_subdivisions=12, y_subdivisions=12)) == 'PLANE'
    cube = _primitive("cube", scale=(1.0, 2.0, 0.5))
    assert shape(cube) == 'BOX'
    assert shape(_primitive("ico_sphere")) == 'MESH'
    assert shape(_primitive("monkey")) == 'MESH'
    assert shape(_primitive("circle", fill_type='NGON')) == 'MESH'  # flat, but no rectangle
    cube.modifiers.new("Bend", 'SIMPLE_DEFORM')
    assert shape(cube) == 'MESH'  # it may deform: it collides as its evaluated mesh
    empty = bpy.data.objects.new("Empty", None)
    assert shape(empty) == 'HALF_SPACE'
    bpy.ops.curve.primitive_bezier_curve_add()
    assert shape(bpy.context.object) is None
    # the fitted box matches the cube's corners in its own space
    fit = extract.automatic_collider(_primitive("cube", size=0.5, location=(1.0, 0.0, 0.0)))[1]
    np.testing.assert_allclose(np.diag(fit)[:3], [0.25, 0.25, 0.25], atol=1e-6)


def test_rigid_particle_links_at_their_defaults_make_ropes_that_keep_their_length(physanim_ext,
                                                                                 tmp_path):
    # A default plane emitter with its chain switched on and made rigid, nothing else: every
    # particle is tied to the one born before it by a rod of their distance at birth. The ropes
    # fly and fall; between any two consecutive ids the distance stays what it was at the first
    # frame both were cached, in every later frame (to 1e-6 of it, plus the float32 spacing of
    # the cached coordinates at their size, twice: both ends are rounded).
    ob = _primitive("plane")
    p = ob.physanim.emitter
    p.enabled, p.link, p.link_hard = True, True, True
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    first: dict[int, float] = {}
    checked, lowest = 0, 0.0
    for f, a in _frames(physanim_ext, ob).items():
        ids, x = a["id"], a["position"]
        lowest = min(lowest, float(x[:, 2].min())) if len(x) else lowest
        where = {int(i): k for k, i in enumerate(ids)}
        for i, k in where.items():
            if i + 1 not in where:
                continue
            d = float(np.linalg.norm(x[where[i + 1]] - x[k]))
            if i not in first:
                first[i] = d
            else:
                size = float(np.abs(x[[k, where[i + 1]]]).max())
                rounding = 4.0 * float(np.spacing(np.float32(size)))
                assert abs(d - first[i]) <= 1e-6 * first[i] + rounding, (f, i, d, first[i])
                checked += 1
    assert checked > 10_000
    assert lowest < -5.0  # ropes under gravity: they fell
