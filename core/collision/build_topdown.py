"""Top-down hierarchy building: split each node's triangles in two, one whole level at a time.

A node is split along its longest axis (the kind's :meth:`split_frame`: the bounding box's
longest side, or an OBB's longest axis), triangles going left or right by their centroid's
projection:

* ``"center"``: left when the centroid lies before the centre of the node's volume;
* ``"median"``: the half of the triangles with the smallest projections goes left.

A split fails when one side would be empty (all centroids on one side of the centre, or all at
the same projection for the median); the node then tries its next-longest axis, then the third.
When every axis fails (all centroids coincide) the triangles are halved in their current order.
Nodes stop splitting at ``leaf_size`` triangles.

All nodes of a level are split together: one batched split-frame fit, one projection of every
centroid, one stable sort; the only Python loop runs over levels (and the three axis attempts).
"""
from __future__ import annotations

import numpy as np

from .bounding import BoundingVolume
from .bvh import BVH, Topology, assemble
from .kinds import bounding_volume
from .mesh import TriangleMesh

SPLITS = ("center", "median")


def check_shape_options(arity: int, leaf_size: int) -> None:
    if int(arity) != arity or arity < 2:
        raise ValueError(f"hierarchy arity must be an integer >= 2 (got {arity})")
    if int(leaf_size) != leaf_size or leaf_size < 1:
        raise ValueError(f"leaf_size must be an integer >= 1 (got {leaf_size})")


def build_topdown(mesh: TriangleMesh, kind: str | BoundingVolume = "obb", *,
                  split: str = "center", arity: int = 2, leaf_size: int = 4) -> BVH:
    """Top-down hierarchy over ``mesh``'s triangles.

    Args:
        mesh: the triangles.
        kind: bounding-volume kind or its name (see :data:`.kinds.KINDS`).
        split: ``"center"`` or ``"median"``.
        arity: children per node (2 = binary; larger collapses the binary tree).
        leaf_size: maximum triangles per leaf.
    """
    kind = bounding_volume(kind)
    check_shape_options(arity, leaf_size)
    if split not in SPLITS:
        raise ValueError(f"top-down split must be one of {SPLITS} (got {split!r})")
    tri = mesh.triangle_vertices
    centroid = tri.mean(axis=1)
    n = len(tri)
    order = np.arange(n, dtype=np.int64)
    child = np.full((max(2 * n - 1, 1), 2), -1, dtype=np.int64)
    leaf_first = np.zeros(len(child), dtype=np.int64)
    leaf_count = np.zeros(len(child), dtype=np.int64)
    nodes, first, count = np.array([0]), np.array([0]), np.array([n])
    next_id = 1
    while len(nodes):
        big = count > leaf_size
        leaf_first[nodes[~big]] = first[~big]
        leaf_count[nodes[~big]] = count[~big]
        nodes, first, count = nodes[big], first[big], count[big]
        if len(nodes) == 0:
            break
        left = _split_level(kind, split, tri, centroid, order, first, count)
        ids = next_id + np.arange(2 * len(nodes))
        next_id += len(ids)
        child[nodes] = ids.reshape(-1, 2)
        nodes = ids
        first = np.stack([first, first + left], axis=1).ravel()
        count = np.stack([left, count - left], axis=1).ravel()
    topo = Topology(child[:next_id], leaf_first[:next_id], leaf_count[:next_id], order, 0)
    return assemble(mesh, kind, topo, arity=arity, leaf_size=leaf_size,
                    builder=f"topdown-{split}")


def _split_level(kind, split, tri, centroid, order, first, count) -> np.ndarray:
    """Partition ``order`` in place within each range; returns the left counts (g,)."""
    g = len(first)
    pos = np.repeat(first - (np.cumsum(count) - count), count) + np.arange(count.sum())
    node = np.repeat(np.arange(g), count)
    local = np.arange(len(pos)) - np.repeat(np.cumsum(count) - count, count)
    cen = centroid[order[pos]]
    axes, centre = kind.split_frame(tri[order], first, count)
    left_side = local < np.repeat(count // 2, count)  # the last resort: halve in order
    left = count // 2
    done = np.zeros(g, dtype=bool)
    for k in range(3):
        if done.all():
            break
        axis = axes[:, k]
        proj = np.einsum("ij,ij->i", cen, axis[node])
        if split == "center":
            side = proj < np.repeat(np.einsum("ij,ij->i", centre, axis), count)
            nl = np.bincount(node, weights=side, minlength=g).astype(np.int64)
            ok = (nl > 0) & (nl < count)
        else:
            rank = np.empty(len(pos), dtype=np.int64)
            rank[np.lexsort((proj, node))] = local  # rank within the node, by projection
            side = rank < np.repeat(count // 2, count)
            nl = count // 2
            lo = np.minimum.reduceat(proj, np.cumsum(count) - count)
            hi = np.maximum.reduceat(proj, np.cumsum(count) - count)
            ok = hi > lo
        ok &= ~done
        take = ok[node]
        left_side = np.where(take, side, left_side)
        left = np.where(ok, nl, left)
        done |= ok
    # stable partition within each node: left side first
    key = node * 2 + (~left_side)
    order[pos] = order[pos][np.argsort(key, kind="stable")]
    return left
