"""Collision detection: bounding volumes, hierarchies over mesh triangles, exact primitive tests
and the queries built on them (mesh against mesh, segments and rays against a mesh, closest
points and signed distances). Numpy only; every query reports the seed's cost terms n_v, n_p,
n_u. See each module's docstring for its exactness and rounding policy.
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
from .queries import (MeshContacts, collide, collision_detection,
                      collision_determination)
from .raycast import SegmentHits, ray_hits, segment_hits
from .sat import obb_overlap
from .sphere import Sphere
from .tritri import triangles_overlap

__all__ = [
    "AABB", "BUILDERS", "BVH", "BoundingVolume", "Budget", "ClosestPoints", "ConvexHull", "KDOP",
    "KINDS", "MeshContacts", "OBB", "QueryCost", "SegmentHits", "Sphere", "TriangleMesh",
    "bounding_volume", "build_bottomup", "build_bvh", "build_incremental", "build_topdown",
    "closest_points", "collide", "collision_detection", "collision_determination",
    "convex_hull", "obb_overlap", "ray_hits", "segment_hits", "triangles_overlap",
]
