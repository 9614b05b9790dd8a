"""Every Blender-version difference PhysAnim depends on, in one place (Blender 4.2 LTS to 5.0).

Other add-on modules never test ``bpy.app.version`` or ``hasattr`` on Blender types themselves;
they call the helpers here. Each helper documents the difference it hides. Checked on the pip
``bpy`` builds 4.2.23, 4.5.4 and 5.0.1.

Differences handled:

* **Actions** — 4.2 has legacy actions (``Action.fcurves``). 4.4 added slotted (layered) actions:
  F-curves live in a channelbag of a keyframe strip, per action slot; 4.4/4.5 keep a legacy
  ``Action.fcurves`` proxy that misbehaves on slotted actions, and 5.0 removed it.
  :func:`channelbag_for` returns an object with ``.fcurves`` on all of them.
* **Material node trees** — 4.x materials need ``use_nodes = True`` before they have a node tree;
  5.0 always has one and deprecates ``use_nodes`` (reading or writing it warns).
* **EEVEE** — the engine id is ``BLENDER_EEVEE_NEXT`` in 4.2–4.5 and ``BLENDER_EEVEE`` in 5.0.
  4.2 still carries the legacy ``Material.shadow_method``; 4.5 removed it.
* **Mesh attribute names** — in 4.2–4.5 ``id`` is a built-in mesh attribute that must be ``INT``
  on the ``POINT`` domain (``attributes.new("id", 'FLOAT', ...)`` fails); 5.0 treats it as
  generic. ``attributes.new`` returns None (and prints a warning) instead of raising when a
  layer cannot be created, on all three.
* **Node sockets** — the shader Attribute node's factor output is ``Fac`` in 4.x and ``Factor``
  in 5.0 (:func:`attribute_factor`). Points to Volume's resolution mode is a node property in
  4.x and a menu input socket in 5.0 (:func:`volume_resolution_by_size`). The geometry node
  group ``interface`` API and the other node/socket names PhysAnim uses are identical.
* **Evaluated instances** — ``Object.evaluated_geometry()`` (a ``GeometrySet`` with the
  instances' attributes) exists from 4.5 on (not in 4.2); :data:`HAS_GEOMETRY_SET`. On 4.5 each
  call leaves one 15-byte block that the exit leak checker reports ("Not freed memory blocks:
  1"); harmless, and gone in 5.0.
"""
from __future__ import annotations

import functools
import importlib
import os
import sys
from typing import Any

import bpy
import numpy as np

#: Slotted actions (channelbags, ``AnimData.action_slot``): Blender 4.4 and newer.
HAS_SLOTS: bool = hasattr(bpy.types, "ActionSlot")
#: ``Object.evaluated_geometry()`` / ``bpy.types.GeometrySet``: Blender 4.5 and newer.
HAS_GEOMETRY_SET: bool = hasattr(bpy.types, "GeometrySet")
#: ``Material.use_nodes`` is deprecated (always True) from Blender 5.0 on.
MATERIAL_ALWAYS_HAS_NODES: bool = bpy.app.version >= (5, 0, 0)

_KEYFRAME_PROPS = bpy.types.Keyframe.bl_rna.properties
#: Keyframe interpolation identifier -> the integer ``foreach_set`` expects.
INTERPOLATION: dict[str, int] = {
    item.identifier: item.value for item in _KEYFRAME_PROPS["interpolation"].enum_items
}
_AUTO_CLAMPED: int = {
    item.identifier: item.value for item in _KEYFRAME_PROPS["handle_left_type"].enum_items
}["AUTO_CLAMPED"]


# --------------------------------------------------------------------------------------------
# Actions and keyframes
# --------------------------------------------------------------------------------------------

def channelbag_for(id_data: bpy.types.ID, action: bpy.types.Action | None = None) -> Any:
    """The container of ``id_data``'s F-curves, creating action, slot, layer and strip as needed.

    4.2: returns the (legacy) action itself. 4.4+: returns the channelbag of the action's first
    keyframe strip for the ID's slot. A slot is (re)used when its display name and ID type match
    ``id_data``; otherwise a new one is created and assigned — assigning an action alone leaves
    ``action_slot`` None, and an unassigned slot does not animate anything.

    Args:
        id_data: the animated ID (object, material, ...).
        action: action to use; default: the ID's current action, else a new one. Passing the
            same action for several IDs shares it with one slot per ID on 4.4+; on 4.2 (no
            slots) those IDs would share the same curves, i.e. the same motion.

    Returns:
        An object with an ``fcurves`` collection (``find``/``new``) for ``id_data``.
    """
    anim = id_data.animation_data or id_data.animation_data_create()
    if action is None:
        action = anim.action or bpy.data.actions.new(f"{id_data.name}Action")
    if anim.action != action:
        anim.action = action
    if not HAS_SLOTS:
        return action
    if anim.action_slot is None:
        slot = next((s for s in action.slots
                     if s.target_id_type == id_data.id_type and s.name_display == id_data.name),
                    None)
        anim.action_slot = slot or action.slots.new(id_type=id_data.id_type, name=id_data.name)
    layer = action.layers[0] if len(action.layers) else action.layers.new("Layer")
    strip = layer.strips[0] if len(layer.strips) else layer.strips.new(type='KEYFRAME')
    return strip.channelbag(anim.action_slot, ensure=True)


def action_fcurves(anim_data: bpy.types.AnimData | None) -> list[bpy.types.FCurve]:
    """The F-curves animating an ID through its assigned action (empty when none).

    4.2: all of the action's curves. 4.4+: only the curves of the assigned slot, from every
    keyframe strip (an action shared by several IDs holds other IDs' curves too).
    """
    action = anim_data.action if anim_data is not None else None
    if action is None:
        return []
    if not HAS_SLOTS:
        return list(action.fcurves)
    slot = anim_data.action_slot
    if slot is None:
        return []
    curves: list[bpy.types.FCurve] = []
    for layer in action.layers:
        for strip in layer.strips:
            bag = strip.channelbag(slot) if strip.type == 'KEYFRAME' else None
            if bag is not None:
                curves.extend(bag.fcurves)
    return curves


def curves_of(action: bpy.types.Action | None, slot_identifier: str = "") -> list:
    """The F-curves of ``action`` for the slot ``slot_identifier`` (4.4+; 4.2: all curves)."""
    if action is None:
        return []
    if not HAS_SLOTS:
        return list(action.fcurves)
    slot = next((s for s in action.slots if s.identifier == slot_identifier), None)
    if slot is None:
        return []
    return [fc for layer in action.layers for strip in layer.strips
            if strip.type == 'KEYFRAME' and strip.channelbag(slot) is not None
            for fc in strip.channelbag(slot).fcurves]


def remove_fcurve(id_data: bpy.types.ID, fcurve: bpy.types.FCurve) -> None:
    """Remove one of ``id_data``'s F-curves from its action (4.2) or from the channelbag that
    holds it (4.4+)."""
    action = id_data.animation_data.action
    if not HAS_SLOTS:
        action.fcurves.remove(fcurve)
        return
    slot = id_data.animation_data.action_slot
    for layer in action.layers:
        for strip in layer.strips:
            bag = strip.channelbag(slot) if strip.type == 'KEYFRAME' else None
            if bag is not None and any(fc == fcurve for fc in bag.fcurves):
                bag.fcurves.remove(fcurve)
                return


def fcurve_ensure(bag: Any, data_path: str, index: int = 0) -> bpy.types.FCurve:
    """The F-curve ``data_path[index]`` of a channelbag (or 4.2 action), created when missing.

    Args:
        bag: result of :func:`channelbag_for`.
        data_path: RNA path relative to the animated ID, e.g. ``"location"``.
        index: array index of the channel (0 for non-array properties).
    """
    return bag.fcurves.find(data_path, index=index) or bag.fcurves.new(data_path, index=index)


def set_keys(fcurve: bpy.types.FCurve, frames: np.ndarray, values: np.ndarray,
             interpolation: str = 'LINEAR') -> None:
    """Replace all keys of ``fcurve`` with one key per frame, in bulk (no per-key Python calls).

    ``keyframe_points.add`` + ``foreach_set`` is ~10x faster than ``keyframe_points.insert``.
    Handles are reset to ``AUTO_CLAMPED`` (what ``keyframe_insert`` makes). Boolean channels
    such as ``hide_render`` need ``'CONSTANT'``. Same code on 4.2, 4.5 and 5.0.

    Args:
        fcurve: curve to overwrite.
        frames: (n,) scene frames [frame], any order (the curve is sorted afterwards).
        values: (n,) values at those frames.
        interpolation: a ``Keyframe.interpolation`` identifier applied to every key.

    Raises:
        ValueError: shapes differ or are not 1-D, or ``interpolation`` is unknown.
    """
    frames = np.asarray(frames)
    values = np.asarray(values)
    if frames.ndim != 1 or frames.shape != values.shape:
        raise ValueError(f'keys for "{fcurve.data_path}[{fcurve.array_index}]" need two equal 1-D '
                         f"arrays (got frames {frames.shape}, values {values.shape})")
    if interpolation not in INTERPOLATION:
        raise ValueError(f"unknown interpolation {interpolation!r} "
                         f"(use one of {sorted(INTERPOLATION)})")
    count = len(frames)
    points = fcurve.keyframe_points
    points.clear()
    if count:
        points.add(count)
        co = np.empty(2 * count, np.float32)
        co[0::2] = frames
        co[1::2] = values
        points.foreach_set("co", co)
        points.foreach_set("interpolation", np.full(count, INTERPOLATION[interpolation], np.int32))
        handle_types = np.full(count, _AUTO_CLAMPED, np.int32)
        points.foreach_set("handle_left_type", handle_types)
        points.foreach_set("handle_right_type", handle_types)
    fcurve.update()  # sorts the keys and recomputes the handles


# --------------------------------------------------------------------------------------------
# Node trees and materials
# --------------------------------------------------------------------------------------------

def new_interface_socket(node_group: bpy.types.NodeTree, name: str, in_out: str,
                         socket_type: str) -> bpy.types.NodeTreeInterfaceSocket:
    """Add a socket to a node group's interface (the group's inputs/outputs).

    ``NodeTree.interface.new_socket`` is the API from 4.0 on and identical in 4.2–5.0 (the old
    ``NodeTree.inputs``/``outputs`` were removed in 4.0, below PhysAnim's minimum version).

    Args:
        node_group: the group.
        name: socket name shown on the modifier.
        in_out: ``'INPUT'`` or ``'OUTPUT'``.
        socket_type: socket idname, e.g. ``'NodeSocketGeometry'``, ``'NodeSocketObject'``.
    """
    return node_group.interface.new_socket(name=name, in_out=in_out, socket_type=socket_type)


def interface_sockets(node_group: bpy.types.NodeTree,
                      in_out: str) -> list[bpy.types.NodeTreeInterfaceSocket]:
    """The group's interface sockets of one direction (``'INPUT'``/``'OUTPUT'``), in order."""
    return [item for item in node_group.interface.items_tree
            if item.item_type == 'SOCKET' and item.in_out == in_out]


def set_modifier_input(modifier: bpy.types.NodesModifier,
                       socket: bpy.types.NodeTreeInterfaceSocket, value: Any) -> None:
    """Set a Geometry Nodes modifier's input; ID properties keyed by the socket identifier.

    Writing the ID property does not tag the depsgraph, so the object is tagged here.
    """
    modifier[socket.identifier] = value
    modifier.id_data.update_tag()


def set_material_use_nodes(material: bpy.types.Material) -> bpy.types.NodeTree:
    """Make sure ``material`` has a node tree and return it.

    4.x: new materials have no node tree until ``use_nodes = True``. 5.0: they always have one
    and ``use_nodes`` is deprecated (a ``DeprecationWarning`` on access), so it is not touched.
    """
    if not MATERIAL_ALWAYS_HAS_NODES and not material.use_nodes:
        material.use_nodes = True
    return material.node_tree


def set_material_alpha(material: bpy.types.Material) -> None:
    """Let EEVEE honour a material's alpha (Cycles and Workbench need nothing).

    4.2+ (EEVEE Next) uses ``surface_render_method``: ``'DITHERED'`` (the default) renders alpha
    as stochastic transparency with correct sorting; transparent shadows are
    ``use_transparent_shadow``. The legacy ``blend_method`` still exists as an alias and
    4.2's legacy ``shadow_method`` is ignored by EEVEE Next, so neither is touched.
    """
    material.surface_render_method = 'DITHERED'
    material.use_transparent_shadow = True


def attribute_factor(node: bpy.types.Node) -> bpy.types.NodeSocket:
    """The shader Attribute node's scalar output: ``Fac`` in 4.x, ``Factor`` in 5.0."""
    return node.outputs["Fac"] if "Fac" in node.outputs else node.outputs["Factor"]


def volume_resolution_by_size(node: bpy.types.Node) -> None:
    """Make a Points to Volume node take its Voxel Size input: a node property
    (``resolution_mode = 'VOXEL_SIZE'``) in 4.2 and 4.5, a menu input socket (``'Size'``) in 5.0.
    """
    if hasattr(node, "resolution_mode"):
        node.resolution_mode = 'VOXEL_SIZE'
    else:
        node.inputs["Resolution Mode"].default_value = 'Size'


#: ``options`` for path properties that may hold '//'-relative paths. 4.5 added
#: ``PATH_SUPPORTS_BLEND_RELATIVE`` and warns (RuntimeWarning) when a path property without it is
#: given a '//' path; 4.2 has neither the option nor the warning.
BLEND_RELATIVE_PATH_OPTIONS: set[str] = (
    {'PATH_SUPPORTS_BLEND_RELATIVE'}
    if "is_path_supports_blend_relative" in bpy.types.Property.bl_rna.properties else set()
)


# --------------------------------------------------------------------------------------------
# USD (pxr)
# --------------------------------------------------------------------------------------------

@functools.cache  # the import path is fixed for the process
def usd_modules() -> tuple | None:
    """``(Usd, UsdGeom, Vt, Sdf)`` from Blender's bundled USD, or None where there is none.

    A Blender binary (4.2 and newer) has ``pxr`` on its Python path. The ``bpy`` module from
    PyPI ships it in 4.5 and 5.0 under ``<resources>/python/lib/pythonX.Y/site-packages``, off
    the path (appended here); the 4.2 module has none.
    """
    try:
        importlib.import_module("pxr")
    except ImportError:
        version = f"python{sys.version_info.major}.{sys.version_info.minor}"
        folder = os.path.join(bpy.utils.resource_path('LOCAL'), "python", "lib", version,
                              "site-packages")
        if not os.path.isdir(os.path.join(folder, "pxr")):
            return None
        sys.path.append(folder)
    try:
        from pxr import Sdf, Usd, UsdGeom, Vt
    except ImportError:
        return None
    return Usd, UsdGeom, Vt, Sdf


def usd_site() -> str | None:
    """The folder ``pxr`` imports from (for a child process), or None where there is none."""
    if usd_modules() is None:
        return None
    return os.path.dirname(os.path.dirname(importlib.import_module("pxr").__file__))
