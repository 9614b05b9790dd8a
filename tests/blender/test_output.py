"""Blender output writers: point data, the instancing modifier, bulk keyframes and rendering.

Every test runs on 4.2, 4.5 and 5.0 (``PHYSANIM_BLENDER=...``); version differences are only in
``addon/compat.py``.
"""
from __future__ import annotations

import importlib
import math
import warnings

import bpy
import numpy as np
import pytest
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Euler, Vector

from physanim.tests.blender import probes


def _module(ext, name):
    return importlib.import_module(f"{ext.__name__}.addon.{name}")


@pytest.fixture
def points(physanim_ext):
    return _module(physanim_ext, "points")


@pytest.fixture
def instancing(physanim_ext):
    return _module(physanim_ext, "instancing")


@pytest.fixture
def compat(physanim_ext):
    return _module(physanim_ext, "compat")


def _particles(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {
        "position": rng.normal(size=(n, 3)).astype(np.float32),
        "id": rng.permutation(n).astype(np.int32) + 7,
        "age": rng.random(n, dtype=np.float32) * 50,
        "velocity": rng.normal(size=(n, 3)).astype(np.float32),
        "size": rng.random(n, dtype=np.float32) + 0.1,
        "color": rng.random((n, 4), dtype=np.float32),
    }


def _points_object(name: str = "particles") -> bpy.types.Object:
    obj = bpy.data.objects.new(name, bpy.data.meshes.new(name))
    bpy.context.scene.collection.objects.link(obj)
    return obj


_KEYS = {"FLOAT_VECTOR": ("vector", 3), "FLOAT_COLOR": ("color", 4), "FLOAT2": ("vector", 2)}


def _read(attributes, name: str) -> np.ndarray:
    attribute = attributes[name]
    key, width = _KEYS.get(attribute.data_type, ("value", 1))
    dtype = {"INT": np.int32, "BOOLEAN": np.bool_}.get(attribute.data_type, np.float32)
    buffer = np.empty(len(attribute.data) * width, dtype)
    attribute.data.foreach_get(key, buffer)
    return buffer.reshape(-1, width) if width > 1 else buffer


# ---------------------------------------------------------------------------------- points

@pytest.mark.parametrize("count", [0, 1, 1000, 1_000_000])
def test_points_round_trip_is_exact(points, count):
    mesh = bpy.data.meshes.new("pts")
    arrays = _particles(count)
    arrays["flag"] = np.arange(count) % 3 == 0          # bool   -> BOOLEAN
    arrays["generation"] = np.arange(count, dtype=np.int64)  # int64  -> INT
    arrays["uv"] = np.ones((count, 2))                   # float64 (n, 2) -> FLOAT2
    points.write_points(mesh, arrays)

    assert (len(mesh.vertices), len(mesh.edges), len(mesh.polygons)) == (count, 0, 0)
    expected_types = {"id": "INT", "age": "FLOAT", "velocity": "FLOAT_VECTOR", "size": "FLOAT",
                      "color": "FLOAT_COLOR", "flag": "BOOLEAN", "generation": "INT",
                      "uv": "FLOAT2"}
    for name, data_type in expected_types.items():
        attribute = mesh.attributes[name]
        assert (attribute.data_type, attribute.domain) == (data_type, "POINT"), name
        assert np.array_equal(_read(mesh.attributes, name), arrays[name]), name
    if count:
        assert np.array_equal(_read(mesh.attributes, "position"), arrays["position"])


def test_points_replace_previous_frame(points):
    mesh = bpy.data.meshes.new("pts")
    first = _particles(10, seed=1)
    first["temperature"] = np.full(10, 300.0, np.float32)
    points.write_points(mesh, first)
    second = _particles(4, seed=2)
    points.write_points(mesh, second)
    assert len(mesh.vertices) == 4
    assert "temperature" not in mesh.attributes
    assert np.array_equal(_read(mesh.attributes, "color"), second["color"])
    third = _particles(4, seed=3)  # same count: layers reused in place
    del third["velocity"]
    points.write_points(mesh, third)
    assert "velocity" not in mesh.attributes
    assert np.array_equal(_read(mesh.attributes, "id"), third["id"])
    points.write_points(mesh, {"position": np.zeros((0, 3))})
    assert len(mesh.vertices) == 0 and "id" not in mesh.attributes


def test_points_replace_faces_and_an_attribute_of_another_type(points):
    bpy.ops.mesh.primitive_cube_add()
    mesh = bpy.context.object.data
    mesh.attributes.new("age", 'INT', 'FACE')
    arrays = _particles(8)  # same vertex count as the cube
    points.write_points(mesh, arrays)
    assert (len(mesh.vertices), len(mesh.edges), len(mesh.polygons)) == (8, 0, 0)
    assert (mesh.attributes["age"].data_type, mesh.attributes["age"].domain) == ("FLOAT", "POINT")
    assert np.array_equal(_read(mesh.attributes, "age"), arrays["age"])


def test_points_convert_wide_dtypes(points):
    mesh = bpy.data.meshes.new("pts")
    arrays = {"position": np.arange(12, dtype=np.float64).reshape(4, 3) / 3,
              "id": np.array([1, 2**31 - 1, -5, 0], np.int64), "size": [0.5, 1.0, 1.5, 2.0]}
    points.write_points(mesh, arrays)
    assert np.array_equal(_read(mesh.attributes, "position"),
                          arrays["position"].astype(np.float32))
    assert np.array_equal(_read(mesh.attributes, "id"), arrays["id"].astype(np.int32))
    assert np.array_equal(_read(mesh.attributes, "size"), np.float32(arrays["size"]))


@pytest.mark.parametrize("arrays, message", [
    ({"id": np.arange(3)}, '"position"'),
    ({"position": np.zeros((3, 3)), "age": np.zeros(2)}, 'attribute "age"'),
    ({"position": np.zeros((3, 2))}, 'attribute "position"'),
    ({"position": 1.0}, 'attribute "position"'),
    ({"position": np.zeros((3, 3)), "color": np.zeros((3, 3))}, 'attribute "color"'),
    ({"position": np.zeros((3, 3)), "tensor": np.zeros((3, 3, 3))}, 'attribute "tensor"'),
    ({"position": np.zeros((3, 3)), "label": np.array(["a", "b", "c"])}, 'attribute "label"'),
    ({"position": np.zeros((1, 3)), "id": np.array([2**40])}, 'attribute "id"'),
    ({"position": np.zeros((1, 3)), "id": np.array([2**32 - 1], np.uint32)}, 'attribute "id"'),
    ({"position": np.zeros((1, 3)), "id": np.array([1.5])}, 'attribute "id"'),
    ({"position": np.zeros((1, 3)), ".select_vert": np.ones(1, bool)}, '".select_vert"'),
])
def test_points_reject_bad_input_before_touching_the_mesh(points, arrays, message):
    mesh = bpy.data.meshes.new("pts")
    points.write_points(mesh, _particles(5))
    with pytest.raises(ValueError, match=message):
        points.write_points(mesh, arrays)
    assert len(mesh.vertices) == 5 and "color" in mesh.attributes


def test_points_reserved_name_raises(points):
    with pytest.raises(ValueError, match='"material_index"'):
        points.write_points(bpy.data.meshes.new("pts"),
                            {"position": np.zeros((2, 3)), "material_index": np.zeros(2)})


def test_evaluated_points_follow_each_write(points):
    obj = _points_object()
    for count in (3, 7, 2, 0, 5):
        arrays = _particles(count, seed=count)
        points.write_points(obj.data, arrays)
        evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
        assert len(evaluated.vertices) == count
        if count:
            assert np.array_equal(_read(evaluated.attributes, "position"), arrays["position"])
            assert np.array_equal(_read(evaluated.attributes, "color"), arrays["color"])


# ------------------------------------------------------------------------------ instancing

def _instance_matrices(obj) -> list:
    depsgraph = bpy.context.evaluated_depsgraph_get()
    return [inst.matrix_world.copy() for inst in depsgraph.object_instances
            if inst.is_instance and inst.parent and inst.parent.original == obj]


def _realized_attributes(obj, names):
    """Evaluate ``obj`` with a temporary Realize Instances modifier (works on 4.2 too)."""
    group = bpy.data.node_groups.new("realize", 'GeometryNodeTree')
    group.interface.new_socket(name="Geometry", in_out='INPUT', socket_type='NodeSocketGeometry')
    group.interface.new_socket(name="Geometry", in_out='OUTPUT', socket_type='NodeSocketGeometry')
    group_in, group_out = group.nodes.new('NodeGroupInput'), group.nodes.new('NodeGroupOutput')
    realize = group.nodes.new('GeometryNodeRealizeInstances')
    group.links.new(group_in.outputs[0], realize.inputs[0])
    group.links.new(realize.outputs[0], group_out.inputs[0])
    modifier = obj.modifiers.new("realize", 'NODES')
    modifier.node_group = group
    try:
        mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
        return len(mesh.vertices), {name: _read(mesh.attributes, name) for name in names}
    finally:
        obj.modifiers.remove(modifier)
        bpy.data.node_groups.remove(group)


def test_instancer_places_one_scaled_rotated_instance_per_point(points, instancing):
    obj = _points_object()
    arrays = _particles(6)
    arrays["instance_rotation"] = np.random.default_rng(5).uniform(-3, 3, (6, 3)).astype(np.float32)
    points.write_points(obj.data, arrays)
    modifier = instancing.ensure_instancer(obj)
    assert modifier.name == "physanim_instances"
    assert all(link.is_valid for link in modifier.node_group.links)
    matrices = _instance_matrices(obj)
    assert len(matrices) == 6
    for matrix in matrices:  # instance order is not guaranteed: match by position
        location, rotation, scale = matrix.decompose()
        i = int(np.argmin(np.linalg.norm(arrays["position"] - np.array(location), axis=1)))
        assert np.allclose(location, arrays["position"][i], atol=1e-6)
        assert np.allclose(scale, [arrays["size"][i]] * 3, atol=1e-6)
        expected = Euler(arrays["instance_rotation"][i].tolist()).to_quaternion()
        assert abs(abs(expected.dot(rotation)) - 1) < 1e-5


@pytest.mark.parametrize("extra, expected_scale", [
    ({}, [1.0, 1.0, 1.0]),
    ({"size": np.array([0.25])}, [0.25, 0.25, 0.25]),
    ({"size": np.array([0.25]), "instance_scale": np.array([[1.0, 2.0, 3.0]])}, [1.0, 2.0, 3.0]),
])
def test_instance_scale_falls_back_to_size_then_one(points, instancing, extra, expected_scale):
    obj = _points_object()
    points.write_points(obj.data, {"position": np.zeros((1, 3)), **extra})
    instancing.ensure_instancer(obj)
    (matrix,) = _instance_matrices(obj)
    assert np.allclose(matrix.to_scale(), expected_scale, atol=1e-6)


def test_instances_carry_the_point_attributes(points, instancing, compat):
    obj = _points_object()
    arrays = _particles(5)
    points.write_points(obj.data, arrays)
    instancing.ensure_instancer(obj)
    names = ["color", "id", "age", "velocity", "size"]
    sphere_vertices = len(instancing.default_particle_object().data.vertices)
    # Realize Instances re-hashes "id" (to keep ids unique per vertex), so it is compared below.
    vertex_count, realized = _realized_attributes(obj, names)
    assert vertex_count == 5 * sphere_vertices
    for name in names[:1] + names[2:]:  # each instance's value on all of its realized vertices
        values = np.unique(realized[name], axis=0)
        assert np.array_equal(values, np.unique(arrays[name], axis=0)), name
    direct = probes.evaluated_instance_attributes(obj, bpy.context.evaluated_depsgraph_get(),
                                                  names)
    if compat.HAS_GEOMETRY_SET:  # 4.5+: read the instance domain itself
        order = np.argsort(direct["id"])
        expected = np.argsort(arrays["id"])
        assert len(direct["id"]) == 5
        for name in names:
            assert np.array_equal(direct[name][order], arrays[name][expected]), name
    else:
        assert direct is None


def test_instancer_is_idempotent_and_swaps_the_instance_object(points, instancing):
    obj = _points_object()
    points.write_points(obj.data, _particles(3))
    first = instancing.ensure_instancer(obj)
    group = first.node_group
    assert instancing.ensure_instancer(obj) == first
    assert [m.name for m in obj.modifiers] == ["physanim_instances"]
    assert first.node_group == group and len(bpy.data.node_groups) == 1

    bpy.ops.mesh.primitive_cube_add(location=(5, 5, 5))
    cube = bpy.context.object
    instancing.ensure_instancer(obj, cube)
    assert _realized_attributes(obj, [])[0] == 3 * 8
    instancing.ensure_instancer(obj, None)
    sphere = instancing.default_particle_object()
    assert _realized_attributes(obj, [])[0] == 3 * len(sphere.data.vertices)


def test_instancer_leaves_a_users_data_of_the_same_names_alone(instancing):
    group = bpy.data.node_groups.new("physanim_instancer", 'GeometryNodeTree')
    material = bpy.data.materials.new("physanim_particle")
    shape = bpy.data.objects.new("physanim_particle", None)  # an empty: cannot be the shape
    obj = _points_object()
    modifier = instancing.ensure_instancer(obj)
    for _ in range(2):  # later calls find what the first one built under the taken names
        other = instancing.ensure_instancer(_points_object("other"))
        assert other.node_group == modifier.node_group
    assert modifier.node_group != group and len(group.nodes) == 0
    assert len(bpy.data.node_groups) == len(bpy.data.materials) == 2
    assert len(bpy.data.objects) == 2 + 3  # shape, particles, other, other.001, other.002
    sphere = instancing.default_particle_object()
    assert sphere != shape and sphere.data.materials[0] != material
    assert len(material.node_tree.nodes if material.node_tree else []) <= 2  # untouched


def test_outdated_group_and_material_are_rebuilt(points, instancing):
    obj = _points_object()
    points.write_points(obj.data, _particles(2))
    group = instancing.ensure_instancer(obj).node_group
    material = instancing.particle_material()
    group.nodes.clear()
    material.node_tree.nodes.clear()
    group["physanim_builder"] = material["physanim_builder"] = 0
    assert instancing.ensure_instancer(obj).node_group == group
    assert instancing.particle_material() == material and len(material.node_tree.nodes) == 3
    assert len(_instance_matrices(obj)) == 2


def test_default_particle_object_is_a_unit_sphere_out_of_the_scene(instancing):
    sphere = instancing.default_particle_object()
    assert instancing.default_particle_object() == sphere
    radii = np.linalg.norm([v.co for v in sphere.data.vertices], axis=1)
    assert np.allclose(radii, 1.0, atol=1e-6)
    assert sphere.users_collection == ()  # never renders by itself at the origin
    material = sphere.data.materials[0]
    (attribute,) = [n for n in material.node_tree.nodes if n.bl_idname == 'ShaderNodeAttribute']
    assert (attribute.attribute_type, attribute.attribute_name) == ("INSTANCER", "color")
    assert attribute.outputs["Alpha"].is_linked and attribute.outputs["Color"].is_linked


def test_default_sphere_survives_save_and_reload(points, instancing, tmp_path):
    obj = _points_object()
    points.write_points(obj.data, _particles(4))
    instancing.ensure_instancer(obj)
    path = str(tmp_path / "saved.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    assert len(_instance_matrices(bpy.data.objects["particles"])) == 4


def test_remove_unused_deletes_only_unused_built_data(points, instancing):
    kept, gone = _points_object("kept"), _points_object("gone")
    instancing.ensure_instancer(kept, name="kept_group")
    instancing.ensure_instancer(gone, name="gone_group")
    users_group = bpy.data.node_groups.new("users_group", 'GeometryNodeTree')
    assert instancing.remove_unused() == 0
    bpy.data.objects.remove(gone)
    assert instancing.remove_unused() == 1 and "gone_group" not in bpy.data.node_groups
    bpy.data.objects.remove(kept)
    assert instancing.remove_unused() == 4  # group, sphere object, its mesh, the material
    assert list(bpy.data.node_groups) == [users_group]
    assert len(bpy.data.objects) == len(bpy.data.materials) == 0


def test_particle_material_needs_no_deprecated_api(instancing):
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        instancing.particle_material("fresh")


# ------------------------------------------------------------------------------- keyframes

def test_bulk_keys_evaluate_exactly_at_keyed_frames(compat):
    bpy.ops.mesh.primitive_cube_add()
    obj = bpy.context.object
    scene = bpy.context.scene
    frames = np.arange(1, 41, dtype=np.float32)
    location = np.random.default_rng(3).normal(size=(40, 3)).astype(np.float32)
    hidden = (np.arange(40) % 7 < 3).astype(np.float32)
    bag = compat.channelbag_for(obj)
    for axis in range(3):
        compat.set_keys(compat.fcurve_ensure(bag, "location", axis), frames, location[:, axis])
    compat.set_keys(compat.fcurve_ensure(bag, "hide_render", 0), frames, hidden, 'CONSTANT')
    assert compat.fcurve_ensure(bag, "location", 0) == compat.fcurve_ensure(bag, "location", 0)
    for i in np.random.default_rng(4).permutation(40):  # scrub in random order
        scene.frame_set(int(frames[i]))
        evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
        assert np.array_equal(np.float32(evaluated.matrix_world.translation), location[i])
        assert np.array_equal(np.float32(obj.location), location[i])
        assert obj.hide_render == bool(hidden[i]) == evaluated.hide_render
    scene.frame_set(5, subframe=0.5)  # CONSTANT holds the previous key between frames
    assert obj.hide_render == bool(hidden[4])


def test_set_keys_replaces_keys_and_checks_input(compat):
    obj = bpy.data.objects.new("empty", None)
    bpy.context.scene.collection.objects.link(obj)
    curve = compat.fcurve_ensure(compat.channelbag_for(obj), "location", 2)
    compat.set_keys(curve, [1, 2, 3], [0.0, 1.0, 2.0], 'BEZIER')
    compat.set_keys(curve, [10, 5], [4.0, 3.0])  # unsorted in, sorted out
    keys = np.empty(4, np.float32)
    curve.keyframe_points.foreach_get("co", keys)
    assert keys.tolist() == [5, 3, 10, 4]
    assert {k.interpolation for k in curve.keyframe_points} == {"LINEAR"}
    compat.set_keys(curve, [], [])
    assert len(curve.keyframe_points) == 0
    with pytest.raises(ValueError, match=r"location\[2\]"):
        compat.set_keys(curve, [1, 2], [1.0])
    with pytest.raises(ValueError, match="interpolation"):
        compat.set_keys(curve, [1], [1.0], 'WOBBLY')


def test_action_fcurves_lists_the_assigned_curves(compat):
    obj = bpy.data.objects.new("body", None)
    assert compat.action_fcurves(obj.animation_data) == []
    bag = compat.channelbag_for(obj)
    curves = [compat.fcurve_ensure(bag, "location", i) for i in range(3)]
    assert compat.action_fcurves(obj.animation_data) == curves
    obj.animation_data.action = None
    assert compat.action_fcurves(obj.animation_data) == []


def test_objects_can_share_one_action(compat):
    if not compat.HAS_SLOTS:
        pytest.skip("4.2 legacy actions have one set of curves: sharing one shares the motion")
    objects = [bpy.data.objects.new(f"body{i}", None) for i in range(3)]
    action = bpy.data.actions.new("bake")
    for i, obj in enumerate(objects):
        bpy.context.scene.collection.objects.link(obj)
        curve = compat.fcurve_ensure(compat.channelbag_for(obj, action), "location", 0)
        compat.set_keys(curve, [1, 2], [i, 10.0 * i])
    again = compat.channelbag_for(objects[1], action)  # reuses the object's slot
    assert len(again.fcurves) == 1
    assert [len(compat.action_fcurves(o.animation_data)) for o in objects] == [1, 1, 1]
    bpy.context.scene.frame_set(2)
    assert [o.location.x for o in objects] == [0.0, 10.0, 20.0]
    assert len(action.slots) == 3


# ------------------------------------------------------------------------------- rendering

def _render_scene(engine: str):
    scene = bpy.context.scene
    scene.render.engine = engine
    scene.render.resolution_x, scene.render.resolution_y = 80, 60
    scene.render.film_transparent = True
    scene.render.image_settings.file_format = 'PNG'
    scene.render.image_settings.color_mode = 'RGBA'
    scene.view_settings.view_transform = 'Standard'
    if engine == 'CYCLES':
        scene.cycles.device = 'CPU'
        scene.cycles.samples = 8
        scene.cycles.use_denoising = False
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(camera)
    camera.location = (0.0, -10.0, 0.0)
    camera.rotation_euler = (math.pi / 2, 0.0, 0.0)
    scene.camera = camera
    return scene


def _render(scene, path) -> np.ndarray:
    return probes.render_still(scene, path)  # row 0 is the bottom row


def _pixel(scene, pixels, position):
    u, v, _depth = world_to_camera_view(scene, scene.camera, Vector(position))
    return pixels[int(v * pixels.shape[0]), int(u * pixels.shape[1])]


def _coloured_particles(points, instancing):
    obj = _points_object()
    arrays = {"position": np.array([[-2.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 0.0, 1.5]]),
              "size": np.full(3, 0.7),
              "color": np.array([[1.0, 0.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0], [0.0, 1.0, 0.0, 0.0]])}
    points.write_points(obj.data, arrays)
    instancing.ensure_instancer(obj)
    return arrays["position"]


def test_cycles_renders_each_particle_in_its_colour(points, instancing, tmp_path):
    scene = _render_scene('CYCLES')
    red, blue, invisible = _coloured_particles(points, instancing)
    pixels = _render(scene, tmp_path / "cycles.png")
    r, g, b, a = _pixel(scene, pixels, red)
    assert r > 0.9 and g < 0.05 and b < 0.05 and a > 0.99
    r, g, b, a = _pixel(scene, pixels, blue)
    assert b > 0.9 and r < 0.05 and g < 0.05 and a > 0.99
    assert _pixel(scene, pixels, invisible)[3] < 0.05  # alpha 0: transparent
    assert _pixel(scene, pixels, (0.0, 0.0, 0.0))[3] == 0  # the shape object is not rendered


def test_particle_material_falls_back_to_object_colour(instancing, tmp_path):
    """Not instanced, the INSTANCER attribute reads ``Object.color``: keyed particle objects."""
    scene = _render_scene('CYCLES')
    sphere = instancing.default_particle_object()
    for name, x, colour in (("red", -2.0, (1.0, 0.0, 0.0, 1.0)), ("clear", 2.0, (0, 1.0, 0, 0))):
        obj = bpy.data.objects.new(name, sphere.data)
        scene.collection.objects.link(obj)
        obj.location, obj.color = (x, 0.0, 0.0), colour
    pixels = _render(scene, tmp_path / "object_colour.png")
    r, g, b, a = _pixel(scene, pixels, bpy.data.objects["red"].location)
    assert r > 0.9 and g < 0.05 and b < 0.05 and a > 0.99
    assert _pixel(scene, pixels, bpy.data.objects["clear"].location)[3] < 0.05


def test_workbench_renders_the_instances(points, instancing, tmp_path):
    scene = _render_scene('BLENDER_WORKBENCH')
    red, blue, _invisible = _coloured_particles(points, instancing)
    pixels = _render(scene, tmp_path / "workbench.png")
    assert _pixel(scene, pixels, red)[3] > 0.99 and _pixel(scene, pixels, blue)[3] > 0.99
    assert _pixel(scene, pixels, (0.0, 0.0, 0.0))[3] == 0
    assert (pixels[..., 3] > 0.5).mean() < 0.25  # a few spheres, not a filled frame


def test_a_hidden_instance_object_still_instances(points, instancing, tmp_path):
    scene = _render_scene('CYCLES')
    red, blue, _invisible = _coloured_particles(points, instancing)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, -1.5))
    cube = bpy.context.object
    cube.hide_render = cube.hide_viewport = True
    instancing.ensure_instancer(bpy.data.objects["particles"], cube)
    pixels = _render(scene, tmp_path / "hidden.png")
    assert _pixel(scene, pixels, red)[3] > 0.99 and _pixel(scene, pixels, blue)[3] > 0.99
    assert _pixel(scene, pixels, cube.location)[3] == 0  # the hidden original stays hidden


def test_eevee_renders_colour_and_alpha(points, instancing, compat, tmp_path):
    scene = _render_scene(probes.eevee_engine_id())  # software OpenGL here: keep it tiny
    scene.render.resolution_x, scene.render.resolution_y = 40, 30
    scene.eevee.taa_render_samples = 1
    red, blue, invisible = _coloured_particles(points, instancing)
    pixels = _render(scene, tmp_path / "eevee.png")
    r, g, b, a = _pixel(scene, pixels, red)
    assert r > 0.9 and g < 0.1 and b < 0.1 and a > 0.99
    r, g, b, a = _pixel(scene, pixels, blue)
    assert b > 0.9 and r < 0.1 and g < 0.1 and a > 0.99
    assert _pixel(scene, pixels, invisible)[3] < 0.05
