"""Shared set-up for the sample scenes: camera, light, world, ground material, render settings."""
from __future__ import annotations

import math

import bpy
import numpy as np
from mathutils import Vector


def look_at(ob, target) -> None:
    direction = Vector(target) - ob.location
    ob.rotation_euler = direction.to_track_quat('-Z', 'Y').to_euler()


def stage(scene, camera_location, target, frame_end: int = 120) -> None:
    """Camera, sun, world and frame range; Cycles with few samples renders previews fast."""
    scene.frame_start, scene.frame_end = 1, frame_end
    scene.physanim.frame_start, scene.physanim.frame_end = 1, frame_end
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    cam.location = camera_location
    look_at(cam, target)
    scene.camera = cam
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", 'SUN'))
    sun.data.energy = 3.0
    sun.rotation_euler = (math.radians(40), math.radians(10), math.radians(30))
    scene.collection.objects.link(sun)
    world = bpy.data.worlds.new("World")
    world.color = (0.02, 0.025, 0.035)
    scene.world = world
    r = scene.render
    r.engine = 'CYCLES'
    scene.cycles.device = 'CPU'
    scene.cycles.samples = 24
    if hasattr(scene.cycles, "use_denoising"):
        scene.cycles.use_denoising = False
    r.resolution_x, r.resolution_y, r.resolution_percentage = 640, 360, 100
    r.image_settings.file_format = 'PNG'
    scene.view_settings.view_transform = 'Standard'


def material(name: str, color, emission: float = 0.0):
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    bsdf = next(n for n in mat.node_tree.nodes if n.type == 'BSDF_PRINCIPLED')
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    if emission:
        bsdf.inputs["Emission Color"].default_value = (*color, 1.0)
        bsdf.inputs["Emission Strength"].default_value = emission
    mat.diffuse_color = (*color, 1.0)
    return mat


def add_mesh(scene, name: str, make) -> bpy.types.Object:
    """A mesh object built by a bmesh primitive ``make(bm)`` (no operators: works headless)."""
    import bmesh

    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    make(bm)
    bm.to_mesh(me)
    bm.free()
    ob = bpy.data.objects.new(name, me)
    scene.collection.objects.link(ob)
    return ob


def ground(scene, size: float = 20.0, color=(0.18, 0.2, 0.22)):
    import bmesh

    ob = add_mesh(scene, "Ground", lambda bm: bmesh.ops.create_grid(
        bm, x_segments=1, y_segments=1, size=1.0))
    ob.scale = (size, size, 1.0)
    ob.data.materials.append(material("Ground", color))
    ob.physanim.collider.enabled = True
    ob.physanim.collider.shape = 'HALF_SPACE'
    return ob


#: Attribute type -> (foreach_get key, components, dtype).
_READ = {'INT': ("value", 1, np.int32), 'FLOAT': ("value", 1, np.float32),
         'FLOAT_VECTOR': ("vector", 3, np.float32), 'FLOAT_COLOR': ("color", 4, np.float32)}
INSTANCER = "physanim_instances"  # the instancing modifier PhysAnim adds to a result


def result_points(res) -> dict[str, np.ndarray]:
    """Every point attribute of a particle result object as Blender shows it now, read before
    its instancing modifier: a point cloud's evaluated geometry (the Points output, read from
    USD files by Blender's own modifiers) or a points mesh (the extension's output)."""
    instancer = res.modifiers.get(INSTANCER)
    shown = instancer.show_viewport if instancer is not None else None
    if instancer is not None:
        instancer.show_viewport = False
    try:
        data = res.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
        n = len(data.points) if res.type == 'POINTCLOUD' else len(data.vertices)
        out = {}
        for attribute in data.attributes:
            if (attribute.name.startswith(".") or attribute.domain != 'POINT'
                    or attribute.data_type not in _READ):
                continue
            key, width, dtype = _READ[attribute.data_type]
            buffer = np.empty(n * width, dtype)
            if n:
                attribute.data.foreach_get(key, buffer)
            out[attribute.name] = buffer.reshape(n, width) if width > 1 else buffer
    finally:
        if instancer is not None:
            instancer.show_viewport = shown
    out.setdefault("position", np.empty((0, 3), np.float32))
    return out


def points(scene, emitter_name: str, frame: int) -> dict[str, np.ndarray]:
    """Attributes of an emitter's result points at ``frame`` (read back from Blender); an empty
    frame has every interface attribute, empty."""
    scene.frame_set(frame)
    out = result_points(bpy.data.objects[emitter_name].physanim.emitter.result)
    n = len(out["position"])
    for name, width, dtype in (("id", 1, np.int32), ("age", 1, np.float32),
                               ("velocity", 3, np.float32), ("color", 4, np.float32),
                               ("size", 1, np.float32)):
        if name not in out:
            out[name] = np.zeros((n, width) if width > 1 else n, dtype)
    return out


def grid(scene, name: str, cuts_x: int, cuts_y: int, size: float):
    """A (size x size*cuts_y/cuts_x) grid mesh in the XY plane, centred at the origin."""
    import bmesh

    return add_mesh(scene, name, lambda bm: bmesh.ops.create_grid(
        bm, x_segments=cuts_x, y_segments=cuts_y, size=size / 2.0))


def evaluated_vertices(ob, world: bool = True) -> np.ndarray:
    """Evaluated vertex positions (n, 3) of a mesh object at the current frame."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    me = ob.evaluated_get(depsgraph).data
    co = np.empty(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3).astype(np.float64)
    if world:
        m = np.array(ob.matrix_world)
        co = co @ m[:3, :3].T + m[:3, 3]
    return co


def triangles(ob) -> np.ndarray:
    me = ob.data
    me.calc_loop_triangles()
    tris = np.empty(len(me.loop_triangles) * 3, np.int32)
    me.loop_triangles.foreach_get("vertices", tris)
    return tris.reshape(-1, 3)


def signed_volume(x: np.ndarray, tris: np.ndarray) -> float:
    a, b, c = x[tris[:, 0]], x[tris[:, 1]], x[tris[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def arm_segment(scene, name: str, length: float, parent, color) -> bpy.types.Object:
    """A robot arm's segment: a 0.25 m square bar ``length`` [m] long along its local +Z from
    its joint (its origin), jointed to the top of ``parent`` (None: the base), turning about
    its joint in XYZ Euler."""
    import bmesh

    def make(bm):
        bmesh.ops.create_cube(bm, size=1.0)
        for v in bm.verts:
            v.co.x *= 0.25
            v.co.y *= 0.25
            v.co.z = (v.co.z + 0.5) * length
    ob = add_mesh(scene, name, make)
    ob.data.materials.append(material(name, color))
    if parent is not None:
        ob.parent = parent
        ob.location = (0.0, 0.0, parent["length"])
    ob["length"] = length
    ob.rotation_mode = 'XYZ'
    return ob


ARM_COLORS = ((0.3, 0.3, 0.35), (0.9, 0.45, 0.1), (0.95, 0.6, 0.15))


def robot_arm(scene, segments) -> list:
    """A robot arm of ``segments`` ((name, length) from the base up), each jointed to the top
    of the one before (:func:`arm_segment`), in the arm's colours; its segment objects."""
    parent, joints = None, []
    for (name, length), color in zip(segments, ARM_COLORS):
        parent = arm_segment(scene, name, length, parent, color)
        joints.append(parent)
    return joints


def key_values(ob, path: str, index: int, frames_values) -> None:
    """Keys on ``ob.<path>[index]``: (frame, value) pairs."""
    for frame, value in frames_values:
        getattr(ob, path)[index] = value
        ob.keyframe_insert(path, index=index, frame=frame)


def fcurves(ob) -> list:
    """The F-curves of an object's action (the layered actions of 4.4 and later, or 4.2's)."""
    action = ob.animation_data.action
    if getattr(action, "layers", None):
        return [fc for layer in action.layers for strip in layer.strips
                for bag in strip.channelbags for fc in bag.fcurves]
    return list(action.fcurves)


def crossings(x: np.ndarray, tris: list) -> int:
    """Overlapping triangle pairs that share no vertex (Blender's BVH overlap test): a mesh
    passing through itself."""
    from mathutils.bvhtree import BVHTree

    tree = BVHTree.FromPolygons([Vector(p) for p in x.tolist()], tris)
    return sum(1 for a, b in tree.overlap(tree) if a < b and not set(tris[a]) & set(tris[b]))


def track(scene, names, frames) -> np.ndarray:
    """(frames, objects, 4, 4) world matrices of the objects ``names`` at ``frames``."""
    obs = [bpy.data.objects[n] for n in names]
    out = []
    for f in frames:
        scene.frame_set(f)
        out.append([np.array(ob.matrix_world) for ob in obs])
    return np.array(out)
