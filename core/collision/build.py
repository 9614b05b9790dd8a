"""One entry point for the hierarchy builders, selected by name."""
from __future__ import annotations

from .bounding import BoundingVolume
from .build_bottomup import build_bottomup
from .build_incremental import build_incremental
from .build_topdown import build_topdown
from .bvh import BVH
from .mesh import TriangleMesh

BUILDERS = {"topdown": build_topdown, "bottomup": build_bottomup,
            "incremental": build_incremental}


def build_bvh(mesh: TriangleMesh, kind: str | BoundingVolume = "obb", method: str = "topdown",
              **options) -> BVH:
    """Hierarchy over ``mesh`` by ``method`` (``"topdown"``, ``"bottomup"`` or
    ``"incremental"``) with that builder's keyword ``options`` (``arity``, ``leaf_size``, ...)."""
    try:
        builder = BUILDERS[method]
    except KeyError:
        raise ValueError(f"unknown hierarchy builder {method!r}; use one of "
                         f"{sorted(BUILDERS)}") from None
    return builder(mesh, kind, **options)
