"""Bounding-volume kinds by name, so hierarchies and tools can be configured with a string."""
from __future__ import annotations

from .bounding import BoundingVolume
from .kdop import AABB, KDOP
from .obb import OBB
from .sphere import Sphere

KINDS: dict[str, BoundingVolume] = {
    "sphere": Sphere(),
    "aabb": AABB,
    "obb": OBB("vertices"),
    "obb_hull": OBB("hull", name="obb_hull"),
    "obb_triangles": OBB("triangles", name="obb_triangles"),
    "obb6": OBB("vertices", sat_axes=6, name="obb6"),
    "kdop6": KDOP(6),
    "kdop14": KDOP(14),
    "kdop18": KDOP(18),
    "kdop26": KDOP(26),
}


def bounding_volume(kind: str | BoundingVolume) -> BoundingVolume:
    """The kind named ``kind`` (see :data:`KINDS`), or ``kind`` itself if it already is one."""
    if isinstance(kind, BoundingVolume):
        return kind
    try:
        return KINDS[kind]
    except KeyError:
        raise ValueError(f"unknown bounding volume {kind!r}; use one of {sorted(KINDS)}") from None
