"""One frame of particles as a USD ``Points`` prim in a text layer (``.usda``), for Blender's own
Mesh Sequence Cache modifier: a bake writes one file per frame (``points_000001.usda``, ...) and
the modifier, with its cache file set to a sequence, reads the frame's file — no extension and no
Python needed where the scene plays or renders.

What Blender's USD point reader takes (checked on 4.2, 4.5 and 5.0):

- ``points`` -> ``position``, ``velocities`` -> ``velocity``, ``widths`` -> ``radius`` (half);
- ``float[]`` primvars of vertex interpolation -> FLOAT attributes of the same name.

Other primvar types are not read alike everywhere: 4.2 skips ``int[]``, ``float3[]`` and
``color4f[]``, and a primvar it cannot read also drops every primvar after it (in name order).
So every other attribute is written as ``float[]`` primvars: an (n, k) array ``a`` as
``a_0`` ... ``a_{k-1}``, and integers as floats, which hold them exactly up to 2**24
(:data:`MAX_FLOAT_ID`; larger ones are refused). ``id`` is written as ``physanim_id``: 4.2 and
4.5 point clouds reserve the name ``id`` for an integer attribute and skip a float one. The
add-on rebuilds the typed attributes from these in Geometry Nodes (:func:`attribute_layout`
says how).

Values are printed with 9 significant digits, which reproduces every float32 exactly: the points
Blender reads equal the float32 arrays of the bake's own cache bit for bit.
"""
from __future__ import annotations

import os
from collections.abc import Mapping

import numpy as np

PRIM_NAME = "particles"
PRIM_PATH = "/" + PRIM_NAME
#: Largest particle id a float primvar carries exactly (float32 has a 24-bit significand).
MAX_FLOAT_ID = 2 ** 24
#: Arrays written as the prim's own attributes rather than primvars.
_BUILTIN = ("position", "velocity")
#: Attributes whose primvars take another name (Blender reserves these names for other types).
_RENAMED = {"id": "physanim_id"}
#: Attributes written as no primvar, since Blender's reader gives them already under another
#: name: ``size`` is the radius it makes of ``widths`` (twice the size: doubling and halving a
#: float32 are exact), so a primvar of it would write every frame's sizes twice.
FROM_READER = {"size": "radius"}


def frame_file_name(frame: int) -> str:
    """File name of one frame: Blender takes the frame from the digits before the extension."""
    return f"points_{int(frame):06d}.usda"


def attribute_layout(arrays: Mapping[str, np.ndarray]) -> dict[str, tuple[str, list[str]]]:
    """How each array other than position and velocity is written: name -> (kind, primvars).

    ``kind`` is ``'INT'`` for (n,) integers, ``'FLOAT'`` for (n,) floats, ``'FLOAT_VECTOR'``
    for (n, 3) and ``'FLOAT_COLOR'`` for (n, 4) (RGBA); ``primvars`` are the float primvars
    holding its components, in order — or, for the attributes of :data:`FROM_READER`, the
    one attribute Blender's reader holds it in. Any other shape raises :class:`ValueError`.
    """
    layout: dict[str, tuple[str, list[str]]] = {}
    for name, array in arrays.items():
        if name in _BUILTIN:
            continue
        a = np.asarray(array)
        base = _RENAMED.get(name, name)
        if name in FROM_READER and a.ndim == 1:
            layout[name] = ('FLOAT', [FROM_READER[name]])
        elif a.ndim == 1:
            layout[name] = ('INT' if a.dtype.kind in "biu" else 'FLOAT', [base])
        elif a.ndim == 2 and a.shape[1] in (3, 4):
            kind = {3: 'FLOAT_VECTOR', 4: 'FLOAT_COLOR'}[a.shape[1]]
            layout[name] = (kind, [f"{base}_{k}" for k in range(a.shape[1])])
        else:
            raise ValueError(f'point attribute "{name}": no USD float primvar layout for shape '
                             f"{a.shape} (use (n,), (n, 3) or (n, 4))")
    return layout


def columns(arrays: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Everything one frame's layer holds, checked and as contiguous float32 arrays.

    Returns ``points`` (n, 3), ``velocities`` (n, 3) and ``widths`` (n,) where the arrays have
    ``velocity`` and ``size``, then ``primvars:<name>`` (n,) for every float primvar, in name
    order (as USD lists them).

    Raises:
        ValueError: a non-finite value, an integer beyond :data:`MAX_FLOAT_ID`, or a row count
            that does not match the points'.
    """
    position = np.asarray(arrays["position"])
    n = len(position)
    out = {"points": position.reshape(n, 3)}
    if "velocity" in arrays:
        out["velocities"] = _rows(arrays, "velocity", n).reshape(n, 3)
    if "size" in arrays:
        out["widths"] = 2.0 * _rows(arrays, "size", n)
    primvars = []
    for name, (kind, names) in attribute_layout(arrays).items():
        if name in FROM_READER:
            continue  # written as the prim's own attribute, above
        values = _rows(arrays, name, n)
        if kind == 'INT' and n and np.abs(values).max() > MAX_FLOAT_ID:
            raise ValueError(f'point attribute "{name}": integers up to {MAX_FLOAT_ID:,} fit a '
                             f"float primvar exactly (got {int(np.abs(values).max()):,})")
        table = values.reshape(n, len(names))
        primvars += [(primvar, table[:, k]) for k, primvar in enumerate(names)]
    out.update((f"primvars:{primvar}", column) for primvar, column in sorted(primvars))
    for key, values in out.items():
        values = np.ascontiguousarray(values, np.float32)
        if not np.isfinite(values).all():
            raise ValueError(f'the USD points\' "{key}" hold a non-finite value')
        out[key] = values
    return out


def points_usda(arrays: Mapping[str, np.ndarray], frame: int) -> str:
    """The text of one frame's layer.

    Args:
        arrays: ``position`` (n, 3) [m]; optional ``velocity`` (n, 3) [m/s], ``size`` (n,) [m]
            (a point's radius: ``widths`` is twice it) and any attribute :func:`attribute_layout`
            accepts (``id``, ``age``, ``color``, ...).
        frame: the scene frame, written as the layer's time code.

    Raises:
        ValueError: as :func:`columns`.
    """
    data = columns(arrays)
    lines = ["#usda 1.0", "(", f'    defaultPrim = "{PRIM_NAME}"', f"    startTimeCode = {frame}",
             f"    endTimeCode = {frame}", '    upAxis = "Z"', "    metersPerUnit = 1", ")", "",
             f'def Points "{PRIM_NAME}"', "{"]
    types = {"points": "point3f[]", "velocities": "vector3f[]", "widths": "float[]"}
    for key, values in data.items():
        if key in types:
            lines.append(f"    {types[key]} {key} = {_text(values)}")
        else:
            lines += [f"    float[] {key} = {_text(values)} (", '        interpolation = "vertex"',
                      "    )"]
    lines += ["}", ""]
    return "\n".join(lines)


def _text(values: np.ndarray) -> str:
    """A USD array literal; 9 significant digits reproduce a float32 exactly."""
    flat = values.reshape(-1).tolist()
    item = "%.9g, " if values.ndim == 1 else "(%.9g, %.9g, %.9g), "
    return "[" + (item * len(values)).rstrip(", ") % tuple(flat) + "]"


def _rows(arrays: Mapping[str, np.ndarray], name: str, n: int) -> np.ndarray:
    a = np.asarray(arrays[name])
    if len(a) != n:
        raise ValueError(f'point attribute "{name}" has {len(a)} rows for {n} points')
    return a


def write_points_usda(path: str | os.PathLike, arrays: Mapping[str, np.ndarray],
                      frame: int) -> None:
    """Write one frame's layer as text to ``path``."""
    text = points_usda(arrays, frame)
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(text)
