"""Particle frames as Blender data: a mesh of loose points carrying per-point attributes.

A particle result object is a vertices-only mesh (a PointCloud cannot be resized from Python in
4.2–5.0) whose geometry is replaced every frame with the particles alive at that frame. Every
array is written with one ``foreach_set`` on the attribute's ``data`` (≈0.5 ms per million
float3), never through ``MeshVertex.co`` (≈75 ms) or a Python loop.
"""
from __future__ import annotations

from collections.abc import Mapping

import bpy
import numpy as np

#: Attribute types of the particle attributes named in the public interface.
KNOWN_TYPES: dict[str, str] = {
    "id": 'INT',
    "age": 'FLOAT',
    "velocity": 'FLOAT_VECTOR',
    "size": 'FLOAT',
    "color": 'FLOAT_COLOR',
}

#: data_type -> (foreach key, components per point, numpy dtype).
_LAYOUT: dict[str, tuple[str, int, type]] = {
    'INT': ("value", 1, np.int32),
    'FLOAT': ("value", 1, np.float32),
    'BOOLEAN': ("value", 1, np.bool_),
    'FLOAT2': ("vector", 2, np.float32),
    'FLOAT_VECTOR': ("vector", 3, np.float32),
    'FLOAT_COLOR': ("color", 4, np.float32),
}

_INT32 = np.iinfo(np.int32)


def attribute_type(name: str, array: np.ndarray) -> str:
    """The Blender attribute type an array is stored as.

    Names in :data:`KNOWN_TYPES` have a fixed type. Otherwise the type follows shape and dtype:
    ``(n,)`` bool -> ``BOOLEAN``, ``(n,)`` integer -> ``INT``, ``(n,)`` float -> ``FLOAT``,
    ``(n, 2)`` -> ``FLOAT2``, ``(n, 3)`` -> ``FLOAT_VECTOR``, ``(n, 4)`` -> ``FLOAT_COLOR`` (RGBA).

    Raises:
        ValueError: the shape or dtype has no matching attribute type.
    """
    if name in KNOWN_TYPES:
        return KNOWN_TYPES[name]
    kind = array.dtype.kind
    if array.ndim == 1 and kind == "b":
        return 'BOOLEAN'
    if array.ndim == 1 and kind in "iu":
        return 'INT'
    if array.ndim == 1 and kind == "f":
        return 'FLOAT'
    if array.ndim == 2 and kind in "iuf" and array.shape[1] in (2, 3, 4):
        return {2: 'FLOAT2', 3: 'FLOAT_VECTOR', 4: 'FLOAT_COLOR'}[array.shape[1]]
    raise ValueError(f'point attribute "{name}": no attribute type for an array of shape '
                     f"{array.shape} and dtype {array.dtype} (use (n,) int/float/bool or "
                     "(n, 2|3|4) float)")


def _flat_buffer(name: str, array: np.ndarray, data_type: str, count: int) -> np.ndarray:
    """``array`` as the contiguous, flat buffer ``foreach_set`` takes for ``data_type``."""
    _key, width, dtype = _LAYOUT[data_type]
    expected = (count,) if width == 1 else (count, width)
    if array.shape != expected:
        raise ValueError(f'point attribute "{name}" ({data_type}) must have shape {expected} '
                         f"(got {array.shape})")
    if dtype is np.int32 and array.dtype.kind not in "biu":
        raise ValueError(f'point attribute "{name}" ({data_type}) needs integers (got '
                         f"{array.dtype})")
    if dtype is np.int32 and not np.can_cast(array.dtype, np.int32) and array.size:
        low, high = array.min(), array.max()
        if low < _INT32.min or high > _INT32.max:
            raise ValueError(f'point attribute "{name}": values {low}..{high} do not fit INT '
                             "(32-bit)")
    return np.ascontiguousarray(array, dtype=dtype).reshape(-1)


def _prepare_geometry(mesh: bpy.types.Mesh, count: int) -> None:
    """Make ``mesh`` exactly ``count`` loose vertices, keeping its layers when the count is equal.

    There is no way to remove vertices, and ``vertices.add`` on a mesh with layers reallocates
    and copies every layer (measured: slower than ``clear_geometry`` + fresh layers), so any
    other count, and any edges/faces, start from a cleared mesh. ``clear_geometry`` drops every
    attribute.
    """
    if len(mesh.vertices) == count and not (len(mesh.edges) or len(mesh.loops)
                                            or len(mesh.polygons)):
        return
    mesh.clear_geometry()
    if count:
        mesh.vertices.add(count)


def _sync_layers(mesh: bpy.types.Mesh, types: Mapping[str, str]) -> None:
    """Create/replace point attributes to match ``types`` and drop stale generic ones.

    Only structural changes happen here: ``attributes.new``/``remove`` invalidate Python
    references to other attributes, so values are written afterwards, looked up by name.
    """
    attributes = mesh.attributes
    stale = [a.name for a in attributes
             if not a.is_internal and not a.is_required
             and (a.name not in types or a.domain != 'POINT' or a.data_type != types[a.name])]
    for name in stale:
        attributes.remove(attributes[name])
    for name, data_type in types.items():
        if attributes.get(name) is None and attributes.new(name, data_type, 'POINT') is None:
            # attributes.new returns None (and only prints a warning) when Blender refuses.
            raise ValueError(f'point attribute "{name}" ({data_type}) cannot be created on mesh '
                             f'"{mesh.name}" (the name is reserved by Blender for another type)')


def write_points(mesh: bpy.types.Mesh, arrays: Mapping[str, np.ndarray]) -> None:
    """Replace ``mesh``'s geometry with loose points carrying the given attributes.

    Any edges and faces are removed. Point attributes not in ``arrays`` (other than Blender's
    own) are removed, so the mesh holds exactly this frame. Names, shapes and dtypes are checked
    before the mesh is touched.

    Args:
        mesh: the particle result mesh.
        arrays: ``position`` (n, 3) [m] is required. The interface attributes have fixed types:
            ``id`` (n,) INT, ``age`` (n,) FLOAT [frame], ``velocity`` (n, 3) FLOAT_VECTOR
            [m/s], ``size`` (n,) FLOAT [m], ``color`` (n, 4) FLOAT_COLOR (linear RGBA). Any
            other array is stored with the type :func:`attribute_type` infers. Values are
            converted to float32 / int32 (INT attributes need integer or bool arrays);
            contiguous float32 / int32 arrays are passed without a copy.

    Raises:
        ValueError: ``position`` is missing, an array's length differs from ``position``'s,
            a shape/dtype fits no attribute type, an int does not fit 32 bits, or a name is
            internal (starts with ``.``) or reserved by Blender.
    """
    if "position" not in arrays:
        raise ValueError(f'points for mesh "{mesh.name}" need a "position" array (n, 3)')
    position = np.asarray(arrays["position"])
    count = len(position) if position.ndim else 0  # a scalar then fails the shape check
    types: dict[str, str] = {}
    buffers: dict[str, np.ndarray] = {}
    for name, array in arrays.items():
        if name.startswith("."):
            raise ValueError(f'point attribute "{name}": names starting with "." are Blender '
                             "internal")
        array = np.asarray(array)
        data_type = 'FLOAT_VECTOR' if name == "position" else attribute_type(name, array)
        buffers[name] = _flat_buffer(name, array, data_type, count)
        if name != "position":
            types[name] = data_type

    _prepare_geometry(mesh, count)
    _sync_layers(mesh, types)
    attributes = mesh.attributes
    for name, buffer in buffers.items():
        if not count:
            continue  # an empty mesh has no "position" layer at all
        data_type = 'FLOAT_VECTOR' if name == "position" else types[name]
        attributes[name].data.foreach_set(_LAYOUT[data_type][0], buffer)
    mesh.update()
