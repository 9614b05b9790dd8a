"""Rigid bodies seen from Blender: tagging a primitive with nothing else set bakes it onto the
ground; results are location / rotation_quaternion keys, one per frame, whose evaluated world
transform equals the simulated one (parents and scale too); free bake gives the object's own
animation back; a failed or cancelled bake leaves the previous keys as they were."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

from sample_scenes._common import result_points

FRAME_START, FRAME_END = 1, 48


def _addon(ext, name: str):
    return sys.modules[f"{ext.__name__}.addon.{name}"]


def _scene(tmp_path: Path):
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = FRAME_START, FRAME_END
    scene.physanim.frame_start, scene.physanim.frame_end = FRAME_START, FRAME_END
    scene.render.fps, scene.render.fps_base = 24, 1.0
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "rigid.blend"))
    return scene


def _ground(size=20.0):
    bpy.ops.mesh.primitive_plane_add(size=size, location=(0.0, 0.0, 0.0))
    ob = bpy.context.object
    ob.name = "Ground"
    ob.physanim.collider.enabled = True
    return ob


def _body(kind="cube", location=(0.0, 0.0, 3.0), **props):
    add = {"cube": bpy.ops.mesh.primitive_cube_add, "uv": bpy.ops.mesh.primitive_uv_sphere_add,
           "ico": bpy.ops.mesh.primitive_ico_sphere_add, "monkey": bpy.ops.mesh.primitive_monkey_add,
           "torus": bpy.ops.mesh.primitive_torus_add,
           "cylinder": bpy.ops.mesh.primitive_cylinder_add,
           "cone": bpy.ops.mesh.primitive_cone_add}
    add[kind](location=location)
    ob = bpy.context.object
    ob.physanim.rigid_body.enabled = True
    for key, value in props.items():
        setattr(ob.physanim.rigid_body, key, value)
    return ob


def _curves(ext, ob) -> dict:
    compat = _addon(ext, "compat")
    return {(fc.data_path, fc.array_index): fc for fc in compat.action_fcurves(ob.animation_data)}


def _world(ob, frame: int) -> np.ndarray:
    bpy.context.scene.frame_set(frame)
    return np.array(ob.matrix_world)


def _baked_cube(tmp_path: Path):
    """A default cube baked falling onto the ground, and its world matrices at frames 1, 24
    and 48."""
    _scene(tmp_path)
    _ground()
    cube = _body()
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    return cube, [_world(cube, f) for f in (1, 24, 48)]


def _refused_keeping_keys(ob, before: list, match: str) -> None:
    """The bake fails with a message matching ``match``, and ``ob`` is where its earlier keys
    put it at frames 1, 24 and 48 (``before``)."""
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.physanim.bake()
    for a, f in zip(before, (1, 24, 48)):
        np.testing.assert_allclose(a, _world(ob, f), atol=1e-7)


def test_cube_falls_into_a_default_mesh_collider_and_rests_on_it(physanim_ext, tmp_path):
    """Suzanne as an Automatic collider is a Mesh collider: a cube dropped on her rests on her
    head, not in it — also where her edges cross under the cube's face and edges, between
    her vertices and its corners (an edge of her head went 7 cm into it before edges were
    tested)."""
    _scene(tmp_path)
    bpy.ops.mesh.primitive_monkey_add(location=(0.0, 0.0, 1.0))
    monkey = bpy.context.object
    monkey.physanim.collider.enabled = True
    cube = _body(location=(0.0, 0.2, 3.5))
    cube.scale = (0.2, 0.2, 0.2)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    z = _world(cube, FRAME_END)[2, 3]
    assert 1.0 < z < 3.0  # stopped by the head (its top is near z = 2)
    assert abs(_world(cube, FRAME_END - 1)[2, 3] - z) < 0.01  # resting or nearly
    assert _deepest_edge_in_cube(monkey, cube) < 0.005


def _deepest_edge_in_cube(mesh_object, cube) -> float:
    """[m] how far the edges of ``mesh_object`` reach into ``cube`` (a default cube, scaled
    evenly) at the current frame, sampled at 101 points along each edge; 0 when none does."""
    me = mesh_object.data
    verts = np.array([mesh_object.matrix_world @ v.co for v in me.vertices])
    ends = np.array([tuple(e.vertices) for e in me.edges])
    t = np.linspace(0.0, 1.0, 101)[None, :, None]
    points = (verts[ends[:, 0], None] * (1.0 - t) + verts[ends[:, 1], None] * t).reshape(-1, 3)
    inverse = np.array(cube.matrix_world.inverted())
    local = points @ inverse[:3, :3].T + inverse[:3, 3]  # the default cube: -1..1 on each axis
    scale = float(cube.matrix_world.to_scale()[0])
    return max(0.0, float((1.0 - np.abs(local)).min(axis=1).max()) * scale)


def test_default_cube_falls_and_rests_on_a_default_plane(physanim_ext, tmp_path):
    scene = _scene(tmp_path)
    _ground()
    cube = _body()
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    curves = _curves(physanim_ext, cube)
    assert {("location", i) for i in range(3)} <= set(curves)
    assert {("rotation_quaternion", i) for i in range(4)} <= set(curves)
    assert all(len(fc.keyframe_points) == FRAME_END - FRAME_START + 1 for fc in curves.values())
    assert cube.rotation_mode == 'QUATERNION'
    z = [_world(cube, f)[2, 3] for f in range(FRAME_START, FRAME_END + 1)]
    assert z[0] == pytest.approx(3.0, abs=1e-6)
    assert z[-1] == pytest.approx(1.0, abs=0.01)  # the 2 m cube rests on the plane
    assert max(abs(z[-1] - v) for v in z[-12:]) < 1e-3  # at rest, no jitter
    assert scene.physanim.bake_info.startswith("baked 1 rigid body, frames")  # no emitters


@pytest.mark.parametrize("kind, shape", [("cube", "BOX"), ("uv", "SPHERE"), ("ico", "SPHERE"),
                                         ("monkey", "HULL"), ("torus", "MESH"),
                                         ("cylinder", "HULL"), ("cone", "HULL")])
def test_automatic_shape_follows_what_the_user_sees(physanim_ext, tmp_path, kind, shape):
    _scene(tmp_path)
    ob = _body(kind)
    rigid = _addon(physanim_ext, "rigid")
    settings = rigid.body_settings(ob, bpy.context.evaluated_depsgraph_get(), FRAME_START)
    assert settings.shape == shape


def test_a_default_cylinder_stands_on_its_end(physanim_ext, tmp_path):
    """Its two rings of vertices are all equally far from its centre, which made it a ball of
    radius 1.41 m that rested 1.41 m up: it is its hull, and stands on the ground 1 m up."""
    _scene(tmp_path)
    _ground()
    cylinder = _body("cylinder")
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    m = _world(cylinder, FRAME_END)
    assert m[2, 3] == pytest.approx(1.0, abs=0.005) and m[2, 2] > 0.9999  # upright


@pytest.mark.parametrize("kind, shape", [("plane", "BOX"), ("grid", "BOX"), ("circle", "HULL")])
def test_a_default_flat_mesh_falls_as_a_thin_solid_and_lies_on_the_ground(physanim_ext,
                                                                          tmp_path, kind, shape):
    """A plane, a grid and a circle (vertices only) tagged with nothing else set: each is a
    solid 1 % of its 2 m size thick, centred on it (a plane was refused as flat, and a circle,
    its vertices all equally far from its centre, was taken for a 1 m ball and lay a metre up).
    Dropped tilted, each lies flat on the ground, half its thickness up."""
    _scene(tmp_path)
    _ground(40.0)
    getattr(bpy.ops.mesh, f"primitive_{kind}_add")(location=(0.0, 0.0, 2.0),
                                                   rotation=(0.3, 0.2, 0.0))
    ob = bpy.context.object
    ob.physanim.rigid_body.enabled = True
    rigid = _addon(physanim_ext, "rigid")
    settings = rigid.body_settings(ob, bpy.context.evaluated_depsgraph_get(), FRAME_START)
    assert settings.shape == shape
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    m = _world(ob, FRAME_END)
    assert abs(m[2, 2]) > 0.9999  # its normal is vertical: lying flat
    assert 0.0095 < m[2, 3] < 0.0125  # 2 cm thick, on the ground (soft contact: within 2.5 mm)
    assert abs(_world(ob, FRAME_END - 1)[2, 3] - m[2, 3]) < 1e-4  # at rest


def _l_prism(name="L"):
    """A closed L-shaped prism: the boxes [0, 2] x [0, 1] x [0, 1] and [0, 1] x [1, 2] x [0, 1]
    (the outline extruded along Z)."""
    import bmesh

    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    outline = [(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)]
    face = bm.faces.new([bm.verts.new((x, y, 0.0)) for x, y in outline])
    face.normal_update()
    if face.normal.z > 0:
        face.normal_flip()  # the bottom faces down
    up = bmesh.ops.extrude_face_region(bm, geom=[face])
    bmesh.ops.translate(bm, verts=[v for v in up["geom"] if isinstance(v, bmesh.types.BMVert)],
                        vec=(0.0, 0.0, 1.0))
    bmesh.ops.recalc_face_normals(bm, faces=bm.faces[:])
    bm.to_mesh(me)
    bm.free()
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


@pytest.mark.parametrize("choice, shape", [("AUTO", "MESH"), ("CONVEX_HULL", "HULL")])
def test_a_concave_mesh_weighs_as_the_mesh_not_its_hull(physanim_ext, tmp_path, choice, shape):
    """At the defaults a closed concave mesh collides as itself; as itself or as its convex
    hull, its mass properties are the mesh's own (closed form for the L's two boxes), not the
    hull's."""
    _scene(tmp_path)
    ob = _l_prism()
    ob.physanim.rigid_body.enabled = True
    ob.physanim.rigid_body.shape = choice
    rigid = _addon(physanim_ext, "rigid")
    settings = rigid.body_settings(ob, bpy.context.evaluated_depsgraph_get(), FRAME_START)
    assert settings.shape == shape
    boxes = [(np.array([2.0, 1.0, 1.0]), np.array([1.0, 0.5, 0.5])),
             (np.array([1.0, 1.0, 1.0]), np.array([0.5, 1.5, 0.5]))]
    mass = np.array([np.prod(size) for size, _ in boxes]) / 3.0  # 1 kg, density uniform
    com = sum(m * c for m, (_, c) in zip(mass, boxes))
    inertia = np.zeros((3, 3))
    for m, (size, centre) in zip(mass, boxes):
        d = centre - com
        inertia += np.diag(m * (np.sum(size ** 2) - size ** 2) / 12.0) \
            + m * (d @ d * np.eye(3) - np.outer(d, d))
    props = settings.mass_properties
    assert props.mass == pytest.approx(1.0)
    assert props.volume == pytest.approx(3.0, rel=1e-9)  # its hull holds 3.5
    np.testing.assert_allclose(props.com, com, atol=1e-9)
    np.testing.assert_allclose(props.inertia, inertia, atol=1e-9)


def test_a_default_torus_dropped_over_a_peg_ends_around_it(physanim_ext, tmp_path):
    """Blender's torus with only its Rigid Body box ticked (Automatic: Mesh) falls over a thin
    cylinder (an Automatic collider: Mesh) and lands on the ground around it: the peg passes
    through its hole, which its convex hull (a disc) could not let happen."""
    _scene(tmp_path)
    _ground()
    bpy.ops.mesh.primitive_cylinder_add(radius=0.3, depth=2.0, location=(0.0, 0.0, 1.0))
    peg = bpy.context.object
    peg.physanim.collider.enabled = True
    torus = _body("torus", location=(0.1, 0.0, 3.0))  # major radius 1, minor 0.25
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    m = _world(torus, FRAME_END)
    assert m[2, 3] == pytest.approx(0.25, abs=5e-3)  # lying on the ground
    assert abs(m[2, 2]) > 0.999  # flat
    assert np.hypot(m[0, 3], m[1, 3]) < 0.75 - 0.3  # the peg is in its hole
    ev = torus.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    co = np.array([m[:3, :3] @ v.co + m[:3, 3] for v in ev.vertices])
    assert co[:, 2].min() > -5e-3
    assert np.hypot(co[:, 0], co[:, 1]).min() > 0.3 - 5e-3  # no vertex inside the peg


def test_keys_reproduce_the_simulation_under_a_scaled_rotated_parent(physanim_ext, tmp_path):
    _scene(tmp_path)
    _ground()
    parent = bpy.data.objects.new("Rig", None)
    bpy.context.scene.collection.objects.link(parent)
    parent.location = (1.0, -2.0, 0.5)
    parent.rotation_euler = (0.0, 0.0, math.radians(30.0))
    parent.scale = (2.0, 2.0, 2.0)
    cube = _body(location=(0.0, 0.0, 0.0))
    cube.parent = parent
    cube.location = (0.0, 0.0, 2.0)
    cube.scale = (0.25, 0.25, 0.25)
    bpy.context.view_layer.update()
    start = np.array(cube.matrix_world)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    cache = _addon(physanim_ext, "cache_paths").rigid_cache_dir(bpy.context.scene)
    read_frame = sys.modules[f"{physanim_ext.__name__}.core.cache"].read_frame
    quat = sys.modules[f"{physanim_ext.__name__}.core.rigid.quaternion"]
    for f in (FRAME_START, 20, FRAME_END):
        m = _world(cube, f)
        sim = read_frame(str(Path(cache) / "bodies"), f)
        np.testing.assert_allclose(m[:3, 3], sim["position"][0], atol=1e-4)
        r = quat.to_matrix(sim["rotation"][:1])[0]
        np.testing.assert_allclose(m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0), r, atol=1e-4)
        np.testing.assert_allclose(np.linalg.norm(m[:3, :3], axis=0), 0.5, atol=1e-5)  # scale
    np.testing.assert_allclose(_world(cube, FRAME_START), start, atol=1e-5)


def test_free_bake_gives_the_objects_own_animation_back(physanim_ext, tmp_path):
    _scene(tmp_path)
    _ground()
    cube = _body(location=(0.0, 0.0, 4.0))
    cube.keyframe_insert("location", frame=1)
    cube.location = (3.0, 0.0, 4.0)
    cube.keyframe_insert("location", frame=48)
    own = cube.animation_data.action
    mode = cube.rotation_mode
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert cube.animation_data.action is not own
    assert bpy.ops.physanim.free_bake() == {'FINISHED'}
    assert cube.animation_data.action is own
    assert cube.rotation_mode == mode
    assert _world(cube, 48)[0, 3] == pytest.approx(3.0)


def test_failed_or_cancelled_bake_keeps_the_previous_keys(physanim_ext, tmp_path):
    _scene(tmp_path)
    ground = _ground()
    cube = _body()
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    before = [_world(cube, f) for f in (1, 24, 48)]
    job = _addon(physanim_ext, "bake").BakeJob(bpy.context)
    for _ in range(5):
        job.step(bpy.context)
    job.abort()  # cancelled half-way
    after = [_world(cube, f) for f in (1, 24, 48)]
    for a, b in zip(before, after):
        np.testing.assert_allclose(a, b, atol=1e-7)
    ground.physanim.collider.shape = 'SPHERE'  # a flat-scaled sphere cannot stop rigid bodies
    ground.scale = (1.0, 1.0, 0.1)
    with pytest.raises(RuntimeError, match='collider "Ground".*scaled unevenly'):
        bpy.ops.physanim.bake()
    for a, f in zip(before, (1, 24, 48)):
        np.testing.assert_allclose(a, _world(cube, f), atol=1e-7)


def _cache_files(scene) -> dict[str, bytes]:
    root = Path(bpy.path.abspath(scene.physanim.cache_dir))
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file()}


def test_a_failure_found_while_keying_keeps_every_previous_bake(physanim_ext, tmp_path):
    """Squash & Stretch is checked on the keys, after the simulation (the fuzzer's: a body
    thrown at 18 km/s came to a scale of inf). It used to be found after the caches were
    swapped in and with the bodies' keys half written: the emitter's previous bake was lost,
    the rigid bodies' cache replaced and the cube's keys changed. Now the rigid bodies alone
    fail, keeping their keys and cache, and the rest bakes; alone, nothing changes."""
    scene = _scene(tmp_path)
    _ground()
    cube, emitter = _body(), _body("ico", location=(4.0, 0.0, 3.0))
    emitter.physanim.rigid_body.enabled = False
    emitter.physanim.emitter.enabled = True
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    before = [_world(cube, f) for f in (1, 24, 48)]
    files = _cache_files(scene)
    rigid = {k: v for k, v in files.items() if "rigid" in k}
    assert rigid and len(rigid) < len(files)

    cube.physanim.rigid_body.squash = 20.0
    cube.physanim.rigid_body.initial_velocity = (2.0e4, 0.0, 0.0)
    emitter.physanim.emitter.seed += 1  # the emitter's bake changes
    with pytest.raises(RuntimeError, match=r'rigid body "Cube".*Squash & Stretch.*the rest '
                                           r'baked'):
        bpy.ops.physanim.bake()
    for a, f in zip(before, (1, 24, 48)):
        np.testing.assert_allclose(a, _world(cube, f), atol=1e-7)
    assert cube.rotation_mode == 'QUATERNION' and ("scale", 0) not in _curves(physanim_ext, cube)
    now = _cache_files(scene)
    assert {k: v for k, v in now.items() if "rigid" in k} == rigid
    assert now != files  # the emitter did bake

    emitter.physanim.emitter.enabled = False  # the rigid bodies alone: nothing changes
    with pytest.raises(RuntimeError, match=r'rigid body "Cube".*Squash & Stretch'):
        bpy.ops.physanim.bake()
    for a, f in zip(before, (1, 24, 48)):
        np.testing.assert_allclose(a, _world(cube, f), atol=1e-7)
    assert _cache_files(scene) == now


def test_a_rigid_body_on_an_empty_is_refused_by_name_and_the_keys_stay(physanim_ext, tmp_path):
    """The fuzzer's rigid bodies: an Empty tagged as a rigid body fails the rigid bodies with a
    message naming it and what it is, and the cube's earlier keys stay as they were."""
    cube, before = _baked_cube(tmp_path)
    scene = bpy.context.scene
    handle = bpy.data.objects.new("Handle", None)
    scene.collection.objects.link(handle)
    handle.physanim.rigid_body.enabled = True
    _refused_keeping_keys(cube, before, r'rigid body "Handle".*a mesh object \(this is an '
                          r'Empty\)')


def test_a_spring_mesh_that_is_also_a_rigid_body_is_refused_by_name(physanim_ext, tmp_path):
    """The two roles exclude each other (shared/DESIGN.md): the keys would move the mesh its
    cache already moves. The bake says so, naming the object, and the earlier keys stay."""
    cube, before = _baked_cube(tmp_path)
    cube.physanim.spring_mesh.enabled = True
    _refused_keeping_keys(cube, before, r'object "Cube".*both a spring mesh and a rigid '
                          r'body.*turn one of them off')
    assert "physanim" not in cube.modifiers


def test_a_rigid_body_that_is_also_a_collider_is_refused_unless_animated(physanim_ext,
                                                                          tmp_path):
    """A falling body is already the particles' collider; its collider role was a still copy
    of it where it started (particles came to rest on nothing, 0.5 m above the cube). Refused
    by name, the earlier keys kept. An animated (kinematic) body may be a collider: that
    collider follows its animation, and the body does not collide with it."""
    cube, before = _baked_cube(tmp_path)
    cube.physanim.collider.enabled = True
    _refused_keeping_keys(cube, before, r'object "Cube".*both a rigid body and a collider'
                          r'.*turn Collider off')
    assert bpy.ops.physanim.free_bake() == {'FINISHED'}
    cube.physanim.rigid_body.kinematic = True
    cube.keyframe_insert("location", frame=FRAME_START)
    cube.location.x += 2.0
    cube.keyframe_insert("location", frame=FRAME_END)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert _world(cube, FRAME_END)[0, 3] == pytest.approx(2.0, abs=1e-6)


def test_bake_status_is_outdated_after_an_edit_and_current_after_rebake(physanim_ext, tmp_path):
    scene = _scene(tmp_path)
    _ground()
    cube = _body()
    panels = _addon(physanim_ext, "panels")
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert panels.bake_status(scene)[1] == 'CHECKMARK'
    cube.physanim.rigid_body.mass = 3.0
    assert "outdated" in panels.bake_status(scene)[0]
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert panels.bake_status(scene)[1] == 'CHECKMARK'


def test_particles_land_on_a_falling_rigid_cube(physanim_ext, tmp_path):
    """Rigid bodies step first: the particles meet the cube where it is in each frame."""
    scene = _scene(tmp_path)
    _ground()
    cube = _body(location=(0.0, 0.0, 2.0))
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(0.0, 0.0, 6.0))
    emitter = bpy.context.object
    p = emitter.physanim.emitter
    p.enabled, p.source, p.rate, p.speed, p.lifetime = True, 'FACES', 30.0, 0.0, 200.0
    p.frame_start, p.frame_end = 1, 10
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    scene.frame_set(FRAME_END)
    res = emitter.physanim.emitter.result
    co = result_points(res)["position"]  # the frame's particles (world positions)
    m = np.array(res.matrix_world)
    x = co @ m[:3, :3].T + m[:3, 3]
    top = cube.matrix_world.translation.z + 1.0
    assert abs(cube.matrix_world.translation.z - 1.0) < 0.01  # the cube rests on the plane
    over = (np.abs(x[:, 0]) < 0.95) & (np.abs(x[:, 1]) < 0.95)
    assert over.sum() > 50
    assert (x[over, 2] > top - 0.01).all()  # on the cube, none inside


def test_an_animated_body_keyed_to_let_go_is_thrown_with_its_animations_velocity(
        physanim_ext, tmp_path):
    """A cube animated along a line (keys at frames 1 and 11) with its Animated switch keyed
    on, then off at frame 11: it follows its keys to frame 11, then flies on with the
    velocity they gave it (4.8 m/s along x and z) under gravity, and lands. The bake keys it
    over the whole range; Free Bake gives its own animation (switch included) back."""
    scene = _scene(tmp_path)
    _ground()
    cube = _body(location=(0.0, 0.0, 1.0))
    cube.scale = (0.2, 0.2, 0.2)
    p = cube.physanim.rigid_body
    for frame, where, on in ((1, (0.0, 0.0, 1.0), True), (11, (2.0, 0.0, 3.0), False)):
        cube.location = where
        cube.keyframe_insert("location", frame=frame)
        p.kinematic = on
        cube.keyframe_insert("physanim.rigid_body.kinematic", frame=frame)
    for fc in _curves(physanim_ext, cube).values():
        for k in fc.keyframe_points:
            k.interpolation = 'LINEAR' if fc.data_path == "location" else 'CONSTANT'
    own = cube.animation_data.action
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert cube.animation_data.action is not own  # keyed by the bake
    path = [_world(cube, f)[:3, 3] for f in range(1, 12)]
    np.testing.assert_allclose(path, [(0.2 * k, 0.0, 1.0 + 0.2 * k) for k in range(11)],
                               atol=1e-5)
    fps = scene.render.fps
    v = (_world(cube, 13)[:3, 3] - _world(cube, 12)[:3, 3]) * fps
    t = 1.5 / fps  # the middle of frames 12-13, from the release at 11
    assert v[0] == pytest.approx(4.8, rel=0.02)
    assert v[2] == pytest.approx(4.8 - 9.81 * t, rel=0.02)
    assert 0.2 - 3e-3 < _world(cube, FRAME_END)[2, 3] < 0.35  # landed (on a face or tumbling)
    assert bpy.ops.physanim.free_bake() == {'FINISHED'}
    assert cube.animation_data.action is own


@pytest.mark.parametrize("mode", ['XYZ', 'ZXY', 'QUATERNION', 'AXIS_ANGLE'])
def test_a_rebake_starts_from_the_pose_the_user_set(physanim_ext, tmp_path, mode):
    """A second bake reads the body where it stood before the first (its keys set aside), to
    the last bit: the two bakes' files are identical, and Free Bake gives the pose back
    exactly. (Restoring through a matrix once put re-baked bodies at the origin, and rounding
    their rotation.)"""
    scene = _scene(tmp_path)
    _ground()
    ob = _body(location=(1.5, -2.0, 3.0))
    ob.rotation_mode = mode
    ob.rotation_euler = (0.3, 0.2, 0.1)
    if mode == 'QUATERNION':
        ob.rotation_quaternion = (0.9, 0.1, 0.3, 0.2)
    if mode == 'AXIS_ANGLE':
        ob.rotation_axis_angle = (0.7, 0.2, 0.5, 0.8)
    ob.scale = (1.0, 0.8, 1.2)
    pose = (tuple(ob.location), tuple(ob.rotation_euler), tuple(ob.rotation_quaternion),
            tuple(ob.rotation_axis_angle), tuple(ob.scale))
    folder = Path(bpy.path.abspath(scene.physanim.cache_dir))

    def files():
        return {p.relative_to(folder): p.read_bytes() for p in sorted(folder.rglob("*.npz"))}

    assert bpy.ops.physanim.bake() == {'FINISHED'}
    first = files()
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert files() == first
    start = next(iter(first))
    cache = sys.modules[f"{physanim_ext.__name__}.core.cache"]
    arrays = cache.read_frame(folder / start.parent, FRAME_START)
    assert tuple(arrays["position"][0]) == pytest.approx((1.5, -2.0, 3.0), abs=1e-6)
    assert bpy.ops.physanim.free_bake() == {'FINISHED'}
    assert ob.rotation_mode == mode
    assert (tuple(ob.location), tuple(ob.rotation_euler), tuple(ob.rotation_quaternion),
            tuple(ob.rotation_axis_angle), tuple(ob.scale)) == pose


def test_keyed_quaternions_take_the_short_way_between_frames(physanim_ext):
    """Each key's sign is chosen against the key before as keyed (q and -q are one rotation):
    the same signs as flipping key by key, through runs of turned-over keys and keys at right
    angles (a zero dot keeps the key's own sign)."""
    keys = _addon(physanim_ext, "rigid_keys")
    rng = np.random.default_rng(3)
    q = rng.normal(size=(400, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    q[100:140] = q[99] * np.where(rng.random(40) < 0.5, -1.0, 1.0)[:, None]  # one rotation
    q[200] = [-q[199, 1], q[199, 0], -q[199, 3], q[199, 2]]  # at right angles to the one before
    expected = q.copy()
    for k in range(1, len(expected)):
        if expected[k] @ expected[k - 1] < 0.0:
            expected[k] = -expected[k]
    got = keys._continuous(q)
    assert np.array_equal(got, expected)
    assert (np.einsum("ij,ij->i", got[1:], got[:-1]) >= 0.0).all()
    assert np.array_equal(keys._continuous(q[:1]), q[:1])


def test_bodies_sharing_a_mesh_have_their_shape_found_once(physanim_ext, tmp_path, monkeypatch):
    """Duplicates (one mesh, one scale) are analysed once per bake and get the same shape as
    each alone — a turned one, whose scale read from its world matrix differs in the last
    digits, within single precision; another scale or mesh is analysed on its own."""
    rigid = _addon(physanim_ext, "rigid")
    _scene(tmp_path)
    _ground()
    first = _body("monkey")
    linked = [first.copy() for _ in range(3)]
    for k, ob in enumerate(linked):
        ob.location = (3.0 * (k + 1), 0.0, 3.0)
        bpy.context.scene.collection.objects.link(ob)
    linked[2].scale = (1.0, 2.0, 1.0)
    linked[1].rotation_euler = (0.3, 1.1, -0.7)
    other = _body("cylinder", location=(-3.0, 0.0, 3.0))
    seen = []
    found = rigid.shape_of
    monkeypatch.setattr(rigid, "shape_of", lambda co, *a: seen.append(len(co)) or found(co, *a))
    bake = rigid.RigidBake(bpy.context.scene, [first, *linked, other], "", [])
    bake.prepare(bpy.context.evaluated_depsgraph_get(), FRAME_START, None)
    assert len(seen) == 3  # the monkey, the stretched monkey, the cylinder
    builder = sys.modules[f"{physanim_ext.__name__}.core.rigid"].RigidBodyBuilder()
    for ob in (first, *linked, other):  # each analysed alone
        builder.add_body(rigid.body_settings(ob, bpy.context.evaluated_depsgraph_get(),
                                             FRAME_START))
    assert len(seen) == 8
    alone, model = builder.finalize(), bake.model
    for name in ("body_shape", "body_com", "body_bound", "body_mass", "body_inertia",
                 "hull_points", "body_hull_start", "body_hull_count"):
        assert np.allclose(getattr(model, name), getattr(alone, name), rtol=1e-6,
                           atol=1e-7 * float(model.body_bound.max())), name
        if name.startswith("body_"):  # the unturned duplicates: exactly
            assert np.array_equal(getattr(model, name)[[0, 1, 3, 4]],
                                  getattr(alone, name)[[0, 1, 3, 4]]), name
    assert not np.allclose(model.body_inertia[3], model.body_inertia[0])  # (stretched)
