"""Particle points that play and render without the extension: a USD file per frame read by
Blender's own Mesh Sequence Cache modifier.

The bake writes one USD layer per frame beside its ``.npz`` frames (``usd/points_000001.usdc``;
``.usda`` text where this Blender has no ``pxr``, e.g. the 4.2 ``bpy`` module). The emitter's
result is then a point cloud object whose modifiers are all native::

    Mesh Sequence Cache ("physanim_cache": the file sequence, prim /particles)
      -> Geometry Nodes ("physanim_attributes": outside Start..End no points; the typed
         attributes rebuilt from the float primvars — id INT, color RGBA, instance_* vectors)
      -> Geometry Nodes ("physanim_instances": instancing, see :mod:`.instancing`)

so a render farm node without PhysAnim plays and renders the same pixels. The geometry before
the instancing modifier holds the particles alive at the frame with the interface attributes
``id``, ``age``, ``velocity``, ``size``, ``color`` (and ``radius`` = size, which Blender's point
cloud display uses).
"""
from __future__ import annotations

import os

import bpy

from ..core import usd_points
from . import compat, usd_process

CACHE_MODIFIER = "physanim_cache"
ATTRIBUTES_MODIFIER = "physanim_attributes"
GROUP_NAME = "physanim_usd_points"
STREAM = "usd"
START_INPUT, END_INPUT = "Start", "End"

_TAG = "physanim_usd_layout"  # on node groups built here: the attribute layout they rebuild
_GROUP_VERSION = 1


# --- writing -------------------------------------------------------------------------------------

def file_extension() -> str:
    """``.usdc`` (binary, ~20x faster to write and 10x smaller) where ``pxr`` imports, else
    ``.usda``."""
    return ".usdc" if compat.usd_modules() is not None else ".usda"


def file_number(frame: int, frame_start: int) -> int:
    """The number in the file name of ``frame``: the frame itself, or for a bake starting below
    frame 1, its place counted from 1. Blender reads the number from the digits before the
    extension, without a minus sign; it does not apply the cache file's frame offset to a
    sequence, so a driver maps scene frames to numbers (:func:`_number_driver`)."""
    return frame if frame_start >= 1 else frame - frame_start + 1


def frame_file_name(number: int, extension: str) -> str:
    return os.path.splitext(usd_points.frame_file_name(number))[0] + extension


def save_frame(path, data) -> None:
    """Write one frame's layer; ``data`` is ``(arrays, frame)`` (a cache writer's save)."""
    arrays, frame = data
    if str(path).endswith(".usda"):
        usd_points.write_points_usda(path, arrays, frame)
    else:
        usd_process.save_usdc(str(path), usd_points.columns(arrays), frame, compat.usd_modules())


# --- reading: the result object ------------------------------------------------------------------

def ensure_reader(res, file_rel: str, layout: dict, frame_start: int, frame_end: int) -> None:
    """Point ``res`` (a point cloud object) at a baked file sequence.

    Args:
        res: the result object. file_rel: '//'-relative path of one frame's file (any frame:
            the modifier finds the others by number). layout: :func:`usd_points.attribute_layout`
            of the bake's arrays. frame_start, frame_end: the baked frames (inclusive).
    """
    old = res.modifiers.get(CACHE_MODIFIER)
    if old is not None and old.type != 'MESH_SEQUENCE_CACHE':
        res.modifiers.remove(old)
        old = None
    cache = old or res.modifiers.new(CACHE_MODIFIER, 'MESH_SEQUENCE_CACHE')
    previous = cache.cache_file
    # A fresh cache file for every bake: Blender keeps an open reader per cache file, which
    # would go on showing the replaced bake's frame until the frame changes.
    cache.cache_file = _new_cache_file(file_rel, res.name)
    _number_driver(cache.cache_file, frame_start, frame_end)
    if previous is not None and previous.users == 0 and previous.library is None:
        bpy.data.batch_remove([previous])  # cache_files has no remove()
    cache.object_path = usd_points.PRIM_PATH

    attributes = res.modifiers.get(ATTRIBUTES_MODIFIER)
    if attributes is not None and attributes.type != 'NODES':
        res.modifiers.remove(attributes)
        attributes = None
    attributes = attributes or res.modifiers.new(ATTRIBUTES_MODIFIER, 'NODES')
    group = _ensure_group(layout)
    if attributes.node_group != group:
        attributes.node_group = group
    sockets = {s.name: s for s in compat.interface_sockets(group, 'INPUT')}
    compat.set_modifier_input(attributes, sockets[START_INPUT], int(frame_start))
    compat.set_modifier_input(attributes, sockets[END_INPUT], int(frame_end))
    _order_first(res, (CACHE_MODIFIER, ATTRIBUTES_MODIFIER))


def _new_cache_file(file_rel: str, label: str):
    before = set(bpy.data.cache_files)
    with bpy.context.temp_override(**_override()):
        bpy.ops.cachefile.open(filepath=bpy.path.abspath(file_rel))
    made = [cf for cf in bpy.data.cache_files if cf not in before]
    if len(made) != 1:
        raise RuntimeError(f'Blender did not open the USD points cache "{file_rel}"')
    cache_file = made[0]
    cache_file.user_clear()  # the operator leaves it one user of its own; the modifier is its user
    cache_file.name = f"{label}_points"
    cache_file.filepath = file_rel
    cache_file.is_sequence = True
    return cache_file


def _number_driver(cache_file, frame_start: int, frame_end: int) -> None:
    """Look files up by the scene frame held inside the baked frames, numbered as
    :func:`file_number`: a driver with a simple expression, which Blender evaluates without
    Python (so it plays where scripts are disabled or PhysAnim is missing).

    Outside the baked frames there is no file: a reader first made there (a bake of frames
    1001-1100 seen from frame 1, a file opened at a frame after the end) failed, and the
    modifier showed "Could not create cache reader" until the frame entered the bake. The
    attributes modifier shows no points outside Start..End, so which file is read there is
    never seen."""
    cache_file.override_frame = True
    curve = cache_file.driver_add("frame")
    curve.driver.type = 'SCRIPTED'
    shift = file_number(0, frame_start)
    held = f"min(max(frame, {int(frame_start)}), {int(frame_end)})"
    curve.driver.expression = held if shift == 0 else f"{held} + {shift}"


def _override() -> dict:
    """A context for ``cachefile.open``, which needs only a window manager (none in some
    background states)."""
    wm = bpy.context.window_manager or bpy.data.window_managers[0]
    return {"window_manager": wm}


def _order_first(res, names) -> None:
    """Put the named modifiers first, in that order (the instancer stays after them)."""
    for index, name in enumerate(names):
        current = list(res.modifiers).index(res.modifiers[name])
        if current != index:
            res.modifiers.move(current, index)


def remove_reader(res) -> None:
    """Remove the reader modifiers and their cache file (before deleting or reusing ``res``)."""
    cache = res.modifiers.get(CACHE_MODIFIER)
    cache_file = cache.cache_file if cache is not None and cache.type == 'MESH_SEQUENCE_CACHE' \
        else None
    for name in (CACHE_MODIFIER, ATTRIBUTES_MODIFIER):
        modifier = res.modifiers.get(name)
        if modifier is not None:
            res.modifiers.remove(modifier)
    if cache_file is not None and cache_file.users == 0 and cache_file.library is None:
        bpy.data.batch_remove([cache_file])


def remove_unused() -> None:
    for group in [g for g in bpy.data.node_groups
                  if g.library is None and g.users == 0 and _TAG in g]:
        bpy.data.node_groups.remove(group)


# --- the attributes node group -------------------------------------------------------------------

def _signature(layout: dict) -> str:
    return ";".join(f"{name}:{kind}:{','.join(names)}"
                    for name, (kind, names) in sorted(layout.items()))


def _ensure_group(layout: dict):
    """The node group rebuilding ``layout``'s typed attributes: shared by every result with the
    same layout, rebuilt when built by an older version."""
    signature = _signature(layout)
    for group in bpy.data.node_groups:
        if group.library is None and group.get(_TAG) == signature:
            if group.get("physanim_version") != _GROUP_VERSION:
                _build_group(group, layout)
                group["physanim_version"] = _GROUP_VERSION
            return group
    group = bpy.data.node_groups.new(GROUP_NAME, 'GeometryNodeTree')
    _build_group(group, layout)
    group[_TAG] = signature
    group["physanim_version"] = _GROUP_VERSION
    return group


def _build_group(group, layout: dict) -> None:
    """Geometry -> delete every point outside Start..End -> store each typed attribute from its
    float primvars (size from the reader's radius) -> remove those primvars -> Geometry."""
    group.nodes.clear()
    group.interface.clear()
    compat.new_interface_socket(group, "Geometry", 'INPUT', 'NodeSocketGeometry')
    for name in (START_INPUT, END_INPUT):
        socket = compat.new_interface_socket(group, name, 'INPUT', 'NodeSocketInt')
        socket.description = f"{name} frame of the bake: no points outside it"
    compat.new_interface_socket(group, "Geometry", 'OUTPUT', 'NodeSocketGeometry')
    group.is_modifier = True
    nodes, links = group.nodes, group.links
    group_in = nodes.new('NodeGroupInput')
    group_in.location = (-1200, 0)
    time = nodes.new('GeometryNodeInputSceneTime')
    time.location = (-1200, -250)
    before = _compare(group, 'LESS_THAN', (-1000, -200))
    after = _compare(group, 'GREATER_THAN', (-1000, -400))
    outside = nodes.new('FunctionNodeBooleanMath')
    outside.operation = 'OR'
    outside.location = (-800, -300)
    delete = nodes.new('GeometryNodeDeleteGeometry')
    delete.domain = 'POINT'
    delete.location = (-600, 0)
    links.new(time.outputs["Frame"], before.inputs[0])
    links.new(group_in.outputs[START_INPUT], before.inputs[1])
    links.new(time.outputs["Frame"], after.inputs[0])
    links.new(group_in.outputs[END_INPUT], after.inputs[1])
    links.new(before.outputs[0], outside.inputs[0])
    links.new(after.outputs[0], outside.inputs[1])
    links.new(group_in.outputs["Geometry"], delete.inputs["Geometry"])
    links.new(outside.outputs[0], delete.inputs["Selection"])

    geometry = delete.outputs["Geometry"]
    x = -400
    removed = []
    for name, (kind, names) in sorted(layout.items()):
        if kind == 'FLOAT' and names == [name]:
            continue  # read as it is
        value = _combined(group, kind, names, (x, -300))
        store = nodes.new('GeometryNodeStoreNamedAttribute')
        store.data_type = kind
        store.domain = 'POINT'
        store.inputs["Name"].default_value = name
        store.location = (x, 0)
        links.new(geometry, store.inputs["Geometry"])
        links.new(value, _value_input(store, kind))
        geometry = store.outputs["Geometry"]
        # (the attributes the reader makes, e.g. radius, stay)
        removed += [n for n in names if n != name and n not in usd_points.FROM_READER.values()]
        x += 250
    for primvar in removed:
        remove = nodes.new('GeometryNodeRemoveAttribute')
        remove.inputs["Name"].default_value = primvar
        remove.location = (x, 0)
        links.new(geometry, remove.inputs["Geometry"])
        geometry = remove.outputs["Geometry"]
        x += 200
    group_out = nodes.new('NodeGroupOutput')
    group_out.location = (x + 100, 0)
    links.new(geometry, group_out.inputs["Geometry"])


def _compare(group, operation: str, location):
    node = group.nodes.new('FunctionNodeCompare')
    node.data_type = 'FLOAT'
    node.operation = operation
    node.location = location
    return node


def _named_float(group, name: str, location):
    node = group.nodes.new('GeometryNodeInputNamedAttribute')
    node.data_type = 'FLOAT'
    node.inputs["Name"].default_value = name
    node.location = location
    return node.outputs["Attribute"]


def _combined(group, kind: str, names: list[str], location):
    """The output socket giving the attribute's value from its float primvars."""
    x, y = location
    columns = [_named_float(group, n, (x - 400, y - 150 * k)) for k, n in enumerate(names)]
    if kind in ('INT', 'FLOAT'):
        return columns[0]  # the float -> int conversion is exact below 2**24
    if kind == 'FLOAT_VECTOR':
        node = group.nodes.new('ShaderNodeCombineXYZ')
    else:
        node = group.nodes.new('FunctionNodeCombineColor')
    node.location = (x - 200, y)
    for k, column in enumerate(columns):
        group.links.new(column, node.inputs[k])
    return node.outputs[0]


def _value_input(store, kind: str):
    """Store Named Attribute's value socket of ``kind`` (one socket in 4.2+, typed by
    ``data_type``; the first enabled one named Value)."""
    return next(s for s in store.inputs if s.name == "Value" and s.enabled)
