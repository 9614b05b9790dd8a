"""Rendering particles: a Geometry Nodes modifier that instances an object on every point.

The result object's points (see :mod:`.points`) go through one node group::

    Group Input ── Geometry ───────────────────────────► Instance on Points ──► Group Output
               └── Instance (object) ─► Object Info ─────►  Instance
    "instance_scale" (float3), else "size" (uniform), else 1 ─►  Scale
    "instance_rotation" (float3, XYZ Euler [rad]) ─────────────►  Rotation

(the quoted names are point attributes read with Named Attribute nodes).

Instance on Points copies every point attribute (``color``, ``id``, ``age``, ``velocity``,
``size``, ...) to the instance domain; shaders read them with an Attribute node of type
``INSTANCER``. The instanced object is an input of the modifier, so users can swap it in the
modifier panel; calling :func:`ensure_instancer` again sets it from code. Object Info uses the
``ORIGINAL`` transform space, so the shape object's own location, rotation and scale do not
move the particles, and ``As Instance`` is off, so the shape's geometry (with its materials)
is instanced directly.
"""
from __future__ import annotations

import bmesh
import bpy

from . import compat

MODIFIER_NAME = "physanim_instances"
DEFAULT_GROUP_NAME = "physanim_instancer"
DEFAULT_OBJECT_NAME = "physanim_particle"
MATERIAL_NAME = "physanim_particle"
INSTANCE_INPUT = "Instance"

#: Custom properties marking data built by this module: the layout version and the name it was
#: asked for (Blender appends ".001" when a user's data block already has that name). A node
#: group or material with an older version is rebuilt; one without the tag (a user's) is never
#: touched.
_TAG = BUILT_TAG = "physanim_builder"
_NAME_TAG = "physanim_name"
_GROUP_VERSION = 1
_MATERIAL_VERSION = 1
_SHAPE_VERSION = 1
_SPHERE_SUBDIVISIONS = 2  # 80 faces: round enough up close, cheap for a million instances


def ensure_instancer(result_obj: bpy.types.Object, instance_obj: bpy.types.Object | None = None,
                     name: str = DEFAULT_GROUP_NAME) -> bpy.types.NodesModifier:
    """Add or update the instancing modifier of a particle result object.

    Idempotent: the modifier ``physanim_instances`` and the node group are created once and
    reused; only the instanced object is updated on later calls. A modifier of that name that
    a user pointed at another node group is pointed back at PhysAnim's.

    Args:
        result_obj: the points object (mesh) of an emitter.
        instance_obj: object instanced on every point; None uses
            :func:`default_particle_object` (a unit sphere reading the particle colours).
        name: name of the node group. An existing group of that name built by PhysAnim is
            reused (several result objects may share it: the instance object is a modifier
            input); a user's group of that name is left alone and a new one is made.

    Returns:
        The Geometry Nodes modifier.
    """
    group = ensure_group(name, _build_group, _GROUP_VERSION)
    return ensure_modifier(result_obj, group,
                           {INSTANCE_INPUT: instance_obj or default_particle_object()})


def ensure_modifier(result_obj: bpy.types.Object, group: bpy.types.NodeTree,
                    inputs: dict) -> bpy.types.NodesModifier:
    """The render modifier ``physanim_instances`` of a result, using ``group`` with ``inputs``
    (input name -> value); a modifier of that name of another type is replaced."""
    modifier = result_obj.modifiers.get(MODIFIER_NAME)
    if modifier is not None and modifier.type != 'NODES':
        result_obj.modifiers.remove(modifier)
        modifier = None
    if modifier is None:
        modifier = result_obj.modifiers.new(MODIFIER_NAME, 'NODES')
    if modifier.node_group != group:
        modifier.node_group = group
    sockets = {s.name: s for s in compat.interface_sockets(group, 'INPUT')}
    for input_name, value in inputs.items():
        compat.set_modifier_input(modifier, sockets[input_name], value)
    return modifier


def default_particle_object(name: str = DEFAULT_OBJECT_NAME,
                            material=None) -> bpy.types.Object:
    """The default particle shape: an icosphere of radius 1 [m] with the particle material.

    With radius 1, the instance scale equals the particle ``size`` and gives a sphere of that
    radius. A local mesh object called ``name`` (or the one this function made when the name
    was taken) is reused, its mesh left as the user made it. A new object is linked to no
    scene, so it never renders by itself at the origin; the modifier's reference keeps it in
    the file (it is saved) and pulls it into the depsgraph (viewport and render).

    Args:
        name: object (and mesh) name.
        material: called for the sphere's material (default :func:`particle_material`).
    """
    material = material or particle_material
    obj = bpy.data.objects.get(name)
    if not _usable_shape(obj):
        obj = _find_built(bpy.data.objects, name)
    if _usable_shape(obj):
        if obj.data.library is None and not obj.data.materials:
            obj.data.materials.append(material())
        return obj
    mesh = bpy.data.meshes.new(name)
    sphere = bmesh.new()
    try:
        bmesh.ops.create_icosphere(sphere, subdivisions=_SPHERE_SUBDIVISIONS, radius=1.0)
        sphere.to_mesh(mesh)
    finally:
        sphere.free()
    mesh.shade_smooth()
    mesh.materials.append(material())
    obj = bpy.data.objects.new(name, mesh)
    _tag(mesh, name, _SHAPE_VERSION)
    _tag(obj, name, _SHAPE_VERSION)
    return obj


def particle_material(name: str = MATERIAL_NAME) -> bpy.types.Material:
    """A material showing each instance's ``color`` attribute (RGBA, alpha = transparency).

    Attribute (``INSTANCER``, ``color``) -> Principled Base Color and Emission Color (strength
    1, so colours read well without lights); its Alpha -> Principled Alpha. Instances without a
    ``color`` attribute render white. On an object that is not an instance, ``INSTANCER`` reads
    the object's own ``Object.color`` (RGBA), so the same material also colours one-object-
    per-particle output keyed on ``color`` (checked with Cycles on 4.2, 4.5 and 5.0).

    Args:
        name: material name. A PhysAnim-built material of that name is reused (rebuilt when
            its layout is outdated); a user's material of that name is left alone.
    """
    material = _find_built(bpy.data.materials, name)
    if material is not None and material.get(_TAG) == _MATERIAL_VERSION:
        return material
    if material is None:
        material = bpy.data.materials.new(name)
    tree = compat.set_material_use_nodes(material)
    tree.nodes.clear()
    nodes, links = tree.nodes, tree.links
    attribute = nodes.new('ShaderNodeAttribute')
    attribute.attribute_type = 'INSTANCER'
    attribute.attribute_name = "color"
    attribute.location = (-400, 0)
    shader = nodes.new('ShaderNodeBsdfPrincipled')
    shader.inputs["Emission Strength"].default_value = 1.0
    output = nodes.new('ShaderNodeOutputMaterial')
    output.location = (300, 0)
    links.new(attribute.outputs["Color"], shader.inputs["Base Color"])
    links.new(attribute.outputs["Color"], shader.inputs["Emission Color"])
    links.new(attribute.outputs["Alpha"], shader.inputs["Alpha"])
    links.new(shader.outputs["BSDF"], output.inputs["Surface"])
    compat.set_material_alpha(material)
    _tag(material, name, _MATERIAL_VERSION)
    return material


def remove_unused() -> int:
    """Delete the node groups, shape objects (and meshes) and materials this module built that
    nothing uses any more, e.g. after a bake was freed. User data and anything still used (or
    with a fake user) stays.

    Returns:
        The number of data blocks removed.
    """
    removed = 0
    for collection in (bpy.data.node_groups, bpy.data.objects, bpy.data.meshes,
                       bpy.data.materials):  # in dependency order: users first
        unused = [item for item in collection
                  if item.library is None and item.users == 0
                  and _TAG in item]
        for item in unused:
            collection.remove(item)
        removed += len(unused)
    return removed


def ensure_group(name: str, build, version: int) -> bpy.types.NodeTree:
    """The node group ``name`` that ``build(group)`` makes: reused, rebuilt when built by
    another ``version``, or created."""
    group = _find_built(bpy.data.node_groups, name)
    if group is None or group.bl_idname != 'GeometryNodeTree':
        group = bpy.data.node_groups.new(name, 'GeometryNodeTree')
        build(group)
        _tag(group, name, version)
    elif group.get(_TAG) != version:
        build(group)
        _tag(group, name, version)
    return group


def find_built(collection, name: str):
    """The local data block PhysAnim built when asked for ``name`` (see :func:`tag`)."""
    return _find_built(collection, name)


def tag(item, name: str, version: int) -> None:
    """Mark ``item`` as PhysAnim's, built for ``name`` with layout ``version``."""
    _tag(item, name, version)


def _find_built(collection: bpy.types.bpy_prop_collection, name: str) -> bpy.types.ID | None:
    """The local data block this module built when asked for ``name``, if any."""
    item = collection.get(name)
    if item is not None and item.library is None and _TAG in item:
        return item
    return next((i for i in collection if i.library is None and i.get(_NAME_TAG) == name), None)


def _tag(item: bpy.types.ID, name: str, version: int) -> None:
    item[_TAG] = version
    item[_NAME_TAG] = name


def _usable_shape(obj: bpy.types.Object | None) -> bool:
    return obj is not None and obj.library is None and obj.type == 'MESH'


def named_attribute(group: bpy.types.NodeTree, name: str, data_type: str,
                     location: tuple[float, float]) -> bpy.types.Node:
    node = group.nodes.new('GeometryNodeInputNamedAttribute')
    node.data_type = data_type  # set enums by name: their order differs between versions
    node.inputs["Name"].default_value = name
    node.location = location
    return node


def _switch(group: bpy.types.NodeTree, input_type: str,
            location: tuple[float, float]) -> bpy.types.Node:
    node = group.nodes.new('GeometryNodeSwitch')
    node.input_type = input_type
    node.location = location
    return node


def new_group_interface(group: bpy.types.NodeTree, inputs: list[tuple[str, str]]) -> None:
    """Clear ``group`` and give it Geometry in/out plus ``inputs`` ((name, socket type))."""
    group.nodes.clear()
    group.interface.clear()
    compat.new_interface_socket(group, "Geometry", 'INPUT', 'NodeSocketGeometry')
    for name, socket_type in inputs:
        compat.new_interface_socket(group, name, 'INPUT', socket_type)
    compat.new_interface_socket(group, "Geometry", 'OUTPUT', 'NodeSocketGeometry')
    group.is_modifier = True


def instance_on_points(group: bpy.types.NodeTree, points, instance, x: float = 0.0):
    """Instance on Points of ``instance`` (a geometry socket) on ``points``, scaled by the
    points' ``instance_scale``, else ``size``, else 1, and turned by ``instance_rotation``.
    Returns the node."""
    nodes, links = group.nodes, group.links
    scale = named_attribute(group, "instance_scale", 'FLOAT_VECTOR', (x - 800, -300))
    size = named_attribute(group, "size", 'FLOAT', (x - 800, -450))
    size_or_one = _switch(group, 'FLOAT', (x - 500, -450))
    size_or_one.inputs["False"].default_value = 1.0
    scale_or_size = _switch(group, 'VECTOR', (x - 300, -350))
    rotation = named_attribute(group, "instance_rotation", 'FLOAT_VECTOR', (x - 500, -600))
    on_points = nodes.new('GeometryNodeInstanceOnPoints')
    on_points.location = (x, 0)
    links.new(points, on_points.inputs["Points"])
    links.new(instance, on_points.inputs["Instance"])
    links.new(size.outputs["Exists"], size_or_one.inputs["Switch"])
    links.new(size.outputs["Attribute"], size_or_one.inputs["True"])
    links.new(scale.outputs["Exists"], scale_or_size.inputs["Switch"])
    links.new(size_or_one.outputs["Output"], scale_or_size.inputs["False"])
    links.new(scale.outputs["Attribute"], scale_or_size.inputs["True"])
    links.new(scale_or_size.outputs["Output"], on_points.inputs["Scale"])
    links.new(rotation.outputs["Attribute"], on_points.inputs["Rotation"])  # Euler -> rotation
    return on_points


def object_geometry(group: bpy.types.NodeTree, object_socket, location):
    """The geometry of the object at ``object_socket``, in its own space (see the module
    docstring). Returns the Geometry output."""
    info = group.nodes.new('GeometryNodeObjectInfo')
    info.transform_space = 'ORIGINAL'
    info.inputs["As Instance"].default_value = False
    info.location = location
    group.links.new(object_socket, info.inputs["Object"])
    return info.outputs["Geometry"]


def _build_group(group: bpy.types.NodeTree) -> None:
    """(Re)build the instancing node tree and interface in place (see the module docstring)."""
    new_group_interface(group, [(INSTANCE_INPUT, 'NodeSocketObject')])
    group_in = group.nodes.new('NodeGroupInput')
    group_in.location = (-800, 0)
    instance = object_geometry(group, group_in.outputs[INSTANCE_INPUT], (-500, -100))
    on_points = instance_on_points(group, group_in.outputs["Geometry"], instance)
    group_out = group.nodes.new('NodeGroupOutput')
    group_out.location = (250, 0)
    group.links.new(on_points.outputs["Instances"], group_out.inputs["Geometry"])
