"""Blender facts the Blender-layer tests need and the add-on does not: which id EEVEE has, and
the attributes of evaluated instances (a 4.5+ API)."""
from __future__ import annotations

import bpy
import numpy as np

HAS_GEOMETRY_SET: bool = hasattr(bpy.types, "GeometrySet")


def eevee_engine_id() -> str:
    """The ``scene.render.engine`` value of EEVEE.

    ``BLENDER_EEVEE_NEXT`` in 4.2–4.5, ``BLENDER_EEVEE`` in 5.0 (the enum lists only registered
    engines, so the id is read from it).
    """
    engines = {item.identifier
               for item in bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items}
    return "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in engines else "BLENDER_EEVEE"


def evaluated_instance_attributes(obj: bpy.types.Object, depsgraph: bpy.types.Depsgraph,
                                  names: list[str]) -> dict[str, np.ndarray] | None:
    """Instance-domain attributes of ``obj``'s evaluated geometry (4.5+), or None on 4.2.

    4.2 has no Python access to the attributes of evaluated instances; callers fall back to
    ``depsgraph.object_instances`` (transforms only) or evaluate a Realize Instances copy.

    Args:
        obj: original object with instancing modifiers.
        depsgraph: evaluated depsgraph.
        names: attribute names; each must exist on the instances (unless there are none).

    Returns:
        ``{name: (n,) or (n, k) array}`` (float32, int32 or bool, one row per instance, in the
        instances' order), or None when this Blender cannot read instance attributes.
    """
    if not HAS_GEOMETRY_SET:
        return None
    # The point cloud belongs to the GeometrySet: keep that alive while reading (a temporary
    # GeometrySet frees it -> "StructRNA of type PointCloud has been removed").
    geometry = obj.evaluated_get(depsgraph).evaluated_geometry()
    cloud = geometry.instances_pointcloud()
    if cloud is None:  # no instances at all
        return {name: np.empty(0, np.float32) for name in names}
    count = len(cloud.points)
    result: dict[str, np.ndarray] = {}
    for name in names:
        attribute = cloud.attributes[name]
        key, width = {'FLOAT_COLOR': ("color", 4), 'FLOAT_VECTOR': ("vector", 3),
                      'FLOAT2': ("vector", 2)}.get(attribute.data_type, ("value", 1))
        dtype = {'INT': np.int32, 'BOOLEAN': np.bool_}.get(attribute.data_type, np.float32)
        buffer = np.empty(count * width, dtype)
        attribute.data.foreach_get(key, buffer)
        result[name] = buffer.reshape(count, width) if width > 1 else buffer
    return result


class LabelRecorder:
    """A stand-in for a panel's ``layout`` that records the labels ``draw()`` shows, checks that
    every property it draws exists, and accepts any other call (rows, operators)."""

    def __init__(self, labels: list):
        self.labels = labels

    def label(self, text: str = "", **_kw):
        self.labels.append(text)

    def prop(self, data, name: str, **_kw):
        if name not in data.bl_rna.properties:
            raise AttributeError(f"the panel draws {type(data).__name__}.{name}, which does "
                                 "not exist")
        return LabelRecorder(self.labels)

    def template_ID(self, data, name: str, **kw):  # Blender's name
        return self.prop(data, name)

    def __getattr__(self, name):
        return lambda *args, **kw: LabelRecorder(self.labels)


def image_pixels(path) -> np.ndarray:
    """(height, width, 4) float pixels of an image file; row 0 is the bottom row."""
    image = bpy.data.images.load(str(path))
    width, height = image.size
    pixels = np.empty(width * height * 4, np.float32)
    image.pixels.foreach_get(pixels)
    bpy.data.images.remove(image)
    return pixels.reshape(height, width, 4)


def render_still(scene, path) -> np.ndarray:
    """Render the scene's current frame to ``path`` and return its pixels."""
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    return image_pixels(path)
