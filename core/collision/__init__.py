"""Collision detection: bounding volumes, hierarchies over mesh triangles, exact primitive tests
and the queries built on them. Numpy only; every query reports the seed's cost terms n_v (volume
tests), n_p (primitive tests) and n_u (volumes updated).

Modules, bottom up:

* :mod:`.predicates` exact orientation signs; :mod:`.tritri` exact triangle-triangle overlap.
* :mod:`.mesh` validated triangle meshes; :mod:`.shapes` procedural grids, spheres, boxes.
* Bounding volumes (:mod:`.bounding` interface): :mod:`.sphere`, :mod:`.kdop` (AABB = 6-DOP,
  14/18/26-DOPs), :mod:`.obb` with :mod:`.sat` (15- and 6-axis tests) and :mod:`.hull`
  (quickhull for hull-based OBB fits); :mod:`.kinds` names them.
* Hierarchies: :mod:`.bvh` (flat layout, refit), built by :mod:`.build_topdown`,
  :mod:`.build_bottomup`, :mod:`.build_incremental` (:func:`build_bvh` picks one by name).
* Queries: :mod:`.queries` mesh against mesh (determination, detection, time-critical),
  :mod:`.raycast` segments and rays, :mod:`.distance` closest points and signed distances;
  :mod:`.cost` the cost terms and budgets.

Each module's docstring states its exactness and rounding policy.
"""
from .bounding import BoundingVolume
from .build import BUILDERS, build_bvh
from .build_bottomup import build_bottomup
from .build_incremental import build_incremental
from .build_topdown import build_topdown
from .bvh import BVH
from .cost import Budget, QueryCost
from .distance import ClosestPoints, closest_points
from .hull import ConvexHull, convex_hull
from .kdop import AABB, KDOP
from .kinds import KINDS, bounding_volume
from .mesh import TriangleMesh
from .obb import OBB
from .queries import MeshContacts, collide, collision_detection, collision_determination
from .raycast import SegmentHits, ray_hits, segment_hits
from .sat import obb_overlap
from .sphere import Sphere
from .tritri import triangles_overlap

__all__ = [
    "AABB", "BUILDERS", "BVH", "KDOP", "KINDS", "OBB", "BoundingVolume", "Budget",
    "ClosestPoints", "ConvexHull", "MeshContacts", "QueryCost", "SegmentHits", "Sphere",
    "TriangleMesh", "bounding_volume", "build_bottomup", "build_bvh", "build_incremental",
    "build_topdown", "closest_points", "collide", "collision_detection",
    "collision_determination", "convex_hull", "obb_overlap", "ray_hits", "segment_hits",
    "triangles_overlap",
]
