"""Bottom-up hierarchy building by agglomerative clustering, vectorised per round.

Starting from one cluster per triangle, every round pairs clusters whose best partner is each
other and merges each pair under a new parent, until one cluster remains. A cluster's best
partner is the candidate whose merged volume (the kind's :meth:`merge`, measured by
:meth:`measure`) is smallest. Candidates are the ``window`` clusters on either side of it in
Morton order (Meister & Bittner's "parallel locally-ordered clustering", 2018): sorting the
centroids along a space-filling curve once puts spatial neighbours next to each other, so every
round is a handful of array operations over all clusters instead of a search per cluster.

Flat geometry has zero volume, so merged volumes are measured with every extent grown by
:data:`FLAT_PAD` of the mesh's size: flat clusters then compare by area.
"""
from __future__ import annotations

import numpy as np

from .bounding import BoundingVolume
from .build_topdown import check_shape_options
from .bvh import BVH, Topology, assemble
from .kinds import bounding_volume
from .mesh import TriangleMesh

FLAT_PAD = 1e-3  # relative to the mesh's bounding-box diagonal
MORTON_BITS = 10


def morton_order(points: np.ndarray) -> np.ndarray:
    """Indices sorting (n, 3) points along a 3D Morton (Z-order) curve (10 bits per axis)."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    span = np.where(hi > lo, hi - lo, 1.0)
    q = ((points - lo) / span * (2 ** MORTON_BITS - 1)).astype(np.int64)
    code = np.zeros(len(points), dtype=np.int64)
    for bit in range(MORTON_BITS):
        for axis in range(3):
            code |= ((q[:, axis] >> bit) & 1) << (3 * bit + axis)
    return np.argsort(code, kind="stable")


def build_bottomup(mesh: TriangleMesh, kind: str | BoundingVolume = "obb", *, arity: int = 2,
                   leaf_size: int = 4, window: int = 8) -> BVH:
    """Bottom-up (agglomerative) hierarchy over ``mesh``'s triangles.

    Args:
        mesh: the triangles.
        kind: bounding-volume kind or its name.
        arity: children per node (2 = binary; larger collapses the binary tree).
        leaf_size: maximum triangles per leaf (small subtrees become leaves).
        window: candidates looked at on each side in Morton order.
    """
    kind = bounding_volume(kind)
    check_shape_options(arity, leaf_size)
    if int(window) != window or window < 1:
        raise ValueError(f"bottom-up window must be an integer >= 1 (got {window})")
    tri = mesh.triangle_vertices
    n = len(tri)
    ids = np.arange(n, dtype=np.int64)
    bv = kind.fit_triangles(tri, ids, np.ones(n, dtype=np.int64))
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    pad = FLAT_PAD * max(float(np.linalg.norm(hi - lo)), 1e-300)
    child = np.full((2 * n - 1, 2), -1, dtype=np.int64)
    order = morton_order(tri.mean(axis=1))
    ids, bv = ids[order], bv[order]
    next_id = n
    while len(ids) > 1:
        partner, cost = _best_partners(kind, bv, window, pad)
        me = np.arange(len(ids))
        i = np.nonzero((partner[partner] == me) & (me < partner))[0]
        if len(i) == 0:  # ties can form cycles: merge at least the cheapest pair
            k = int(np.argmin(cost))
            i = np.array([min(k, partner[k])])
        j = partner[i]
        new = next_id + np.arange(len(i))
        next_id += len(i)
        child[new] = np.stack([ids[i], ids[j]], axis=1)
        ids[i] = new
        bv[i] = kind.merge(bv[i], bv[j])
        keep = np.ones(len(ids), dtype=bool)
        keep[j] = False
        ids, bv = ids[keep], bv[keep]
    leaf_first = np.where(np.arange(2 * n - 1) < n, np.arange(2 * n - 1), 0)
    leaf_count = (np.arange(2 * n - 1) < n).astype(np.int64)
    topo = Topology(child, leaf_first, leaf_count, np.arange(n, dtype=np.int64), int(ids[0]))
    return assemble(mesh, kind, topo, arity=arity, leaf_size=leaf_size, builder="bottomup")


def _best_partners(kind, bv, window, pad):
    """Each cluster's cheapest neighbour within ``window`` places, and that merge's cost."""
    c = len(bv)
    best_cost = np.full(c, np.inf)
    partner = np.zeros(c, dtype=np.int64)
    for off in range(1, min(window, c - 1) + 1):
        i = np.arange(c - off)
        cost = kind.measure(kind.merge(bv[i], bv[i + off]), pad)
        for me, other in ((i, i + off), (i + off, i)):  # the cost is symmetric
            better = cost < best_cost[me]
            best_cost[me[better]] = cost[better]
            partner[me[better]] = other[better]
    return partner, best_cost
