"""Bounding-volume hierarchies over the triangles of one mesh, in a flat array layout.

Every builder (:mod:`.build_topdown`, :mod:`.build_bottomup`, :mod:`.build_incremental`) only
decides a binary tree's shape (:class:`Topology`); :func:`assemble` turns any such shape into the
same layout:

* nodes are numbered breadth-first, so the nodes of depth d are
  ``level_start[d]:level_start[d + 1]``;
* ``node_child`` (n, arity) holds child node ids, -1 where a node has fewer children; a leaf
  has none;
* the triangles under a node (at any depth) are ``tri_order[node_first:node_first +
  node_tri_count]``: leaves hold at most ``leaf_size`` triangles, and each subtree's triangles
  are contiguous, so fitting or refitting all nodes of one depth is one batched fit;
* ``node_bv`` (n, kind.width) the volumes, in the kind's packed layout.

k-ary trees (arity > 2) come from collapsing the binary shape: each node pulls up the children
of its largest (most triangles) internal children while it has fewer than ``arity``.

Refitting a deforming mesh keeps the shape and refits only the volumes whose triangles moved,
reporting how many that was: the seed's n_u.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from .bounding import BoundingVolume
from .mesh import TriangleMesh


@dataclass(frozen=True)
class Topology:
    """A builder's binary tree before layout.

    Attributes:
        child: (m, 2) child node ids, -1 for leaves.
        leaf_first: (m,) for leaves, first position of their triangles in ``order``.
        leaf_count: (m,) for leaves, number of triangles (0 for internal nodes).
        order: (n_tri,) triangle ids.
        root: id of the root node.
    """

    child: np.ndarray
    leaf_first: np.ndarray
    leaf_count: np.ndarray
    order: np.ndarray
    root: int


def _frozen(*arrays):
    for a in arrays:
        a.setflags(write=False)


@dataclass(frozen=True, eq=False)
class BVH:
    """Flat bounding-volume hierarchy of one mesh (see the module docstring for the layout).

    Attributes:
        mesh: the mesh (its current vertices) the volumes enclose.
        kind: the bounding-volume kind of ``node_bv``.
        arity: maximum children per node. leaf_size: maximum triangles per leaf.
        builder: how the shape was built (for reports).
        node_bv: (n, kind.width). node_child: (n, arity) int64. node_first, node_tri_count: (n,).
        level_start: (depth + 2,) first node id of each depth (and the node count).
        tri_order: (n_tri,) triangle ids in leaf order.
    """

    mesh: TriangleMesh
    kind: BoundingVolume
    arity: int
    leaf_size: int
    builder: str
    node_bv: np.ndarray
    node_child: np.ndarray
    node_first: np.ndarray
    node_tri_count: np.ndarray
    level_start: np.ndarray
    tri_order: np.ndarray

    @property
    def node_count(self) -> int:
        return len(self.node_bv)

    @property
    def depth(self) -> int:
        """Number of levels below the root."""
        return len(self.level_start) - 2

    @cached_property
    def node_is_leaf(self) -> np.ndarray:
        out = self.node_child[:, 0] < 0
        out.setflags(write=False)
        return out

    @cached_property
    def node_size(self) -> np.ndarray:
        """(n,) diameters [m] of the volumes (traversals descend the larger)."""
        out = self.kind.size(self.node_bv)
        out.setflags(write=False)
        return out

    @cached_property
    def ordered_triangles(self) -> np.ndarray:
        """(n_tri, 3, 3) triangle corners in leaf order [m]."""
        out = self.mesh.triangle_vertices[self.tri_order]
        out.setflags(write=False)
        return out

    def levels(self):
        """Node id ranges, one ``np.arange`` per depth, root first."""
        for d in range(len(self.level_start) - 1):
            yield np.arange(self.level_start[d], self.level_start[d + 1])

    def refit(self, vertices) -> tuple[BVH, int]:
        """The same hierarchy over deformed vertices (n_v, 3) [m].

        Only volumes over triangles with a moved vertex are refitted (each kind's refit; OBBs
        keep their axes). Returns (new hierarchy, n_u = number of volumes updated).
        """
        mesh = self.mesh.with_vertices(vertices)
        moved_v = np.any(mesh.vertices != self.mesh.vertices, axis=1)
        moved_t = moved_v[mesh.triangles].any(axis=1)[self.tri_order]
        cs = np.concatenate([[0], np.cumsum(moved_t)])
        touched = cs[self.node_first + self.node_tri_count] > cs[self.node_first]
        bv = self.node_bv.copy()
        tri = mesh.triangle_vertices[self.tri_order]
        for nodes in self.levels():
            nodes = nodes[touched[nodes]]
            if len(nodes):
                bv[nodes] = self.kind.refit_triangles(bv[nodes], tri, self.node_first[nodes],
                                                      self.node_tri_count[nodes])
        _frozen(bv)
        return replace(self, mesh=mesh, node_bv=bv), int(touched.sum())

    def check(self) -> None:
        """Raise AssertionError unless the layout invariants hold (for tests)."""
        n = self.node_count
        kids = self.node_child
        assert kids.shape == (n, self.arity)
        real = kids >= 0
        assert np.all(real[:, :-1] | ~real[:, 1:]), "children must be packed to the left"
        ids = kids[real]
        assert np.array_equal(np.sort(ids), np.arange(1, n)), "one parent for all but the root"
        internal = ~self.node_is_leaf
        assert np.all(real[internal].sum(axis=1) >= 2), "internal nodes have >= 2 children"
        assert np.all(self.node_tri_count[self.node_is_leaf] <= self.leaf_size)
        for k in range(self.arity):  # children partition their parent's triangle range in order
            has = real[:, k]
            c = kids[has, k]
            parents = np.nonzero(has)[0]
            expect = self.node_first[parents] + sum(
                np.where(real[parents, j], self.node_tri_count[kids[parents, j]], 0)
                for j in range(k))
            assert np.array_equal(self.node_first[c], expect)
        sums = np.where(real, self.node_tri_count[np.where(real, kids, 0)], 0).sum(axis=1)
        assert np.array_equal(sums[internal], self.node_tri_count[internal])
        assert np.array_equal(np.sort(self.tri_order), np.arange(self.mesh.triangle_count))


def assemble(mesh: TriangleMesh, kind: BoundingVolume, topo: Topology, *, arity: int,
             leaf_size: int, builder: str) -> BVH:
    """Lay out a builder's binary tree as a flat :class:`BVH` and fit all its volumes."""
    child, root = topo.child, topo.root
    is_leaf = child[:, 0] < 0
    levels = _binary_levels(child, root)
    count = np.where(is_leaf, topo.leaf_count, 0).astype(np.int64)
    for lev in reversed(levels):
        inner = lev[~is_leaf[lev]]
        count[inner] = count[child[inner, 0]] + count[child[inner, 1]]
    first = np.zeros(len(child), dtype=np.int64)
    for lev in levels:
        inner = lev[~is_leaf[lev]]
        first[child[inner, 0]] = first[inner]
        first[child[inner, 1]] = first[inner] + count[child[inner, 0]]
    order = _leaf_order(topo, np.concatenate(levels), is_leaf, first, count)
    cut = is_leaf | (count <= leaf_size)
    src, kids, level_start = _collapse(child, root, cut, count, first, arity)
    tri = mesh.triangle_vertices[order]
    node_first, node_count = first[src], count[src]
    bv = np.empty((len(src), kind.width))
    for d in range(len(level_start) - 1):
        nodes = np.arange(level_start[d], level_start[d + 1])
        bv[nodes] = kind.fit_triangles(tri, node_first[nodes], node_count[nodes])
    _frozen(bv, kids, node_first, node_count, level_start, order)
    return BVH(mesh, kind, arity, leaf_size, builder, bv, kids, node_first, node_count,
               level_start, order)


def _binary_levels(child: np.ndarray, root: int) -> list[np.ndarray]:
    levels, frontier = [], np.array([root], dtype=np.int64)
    while len(frontier):
        levels.append(frontier)
        kids = child[frontier].ravel()
        frontier = kids[kids >= 0]
    return levels


def _leaf_order(topo: Topology, reached, is_leaf, first, count) -> np.ndarray:
    leaves = reached[is_leaf[reached]]
    n = count[leaves]
    offset = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    order = np.empty(len(topo.order), dtype=np.int64)
    order[np.repeat(first[leaves], n) + offset] = topo.order[np.repeat(topo.leaf_first[leaves],
                                                                       n) + offset]
    return order


def _collapse(child, root, cut, count, first, arity):
    """Breadth-first final tree: node sources (binary ids), children (final ids), levels.

    Each final internal node starts with its two binary children and, while it has a free slot,
    replaces its internal child with the most triangles by that child's two children.
    """
    src = [np.array([root], dtype=np.int64)]
    kid_rows = []
    level_start = [0, 1]
    frontier = src[0]
    while True:
        inner = frontier[~cut[frontier]]
        if len(inner) == 0:
            kid_rows.append(np.full((len(frontier), arity), -1, dtype=np.int64))
            break
        slots = np.full((len(inner), arity), -1, dtype=np.int64)
        slots[:, :2] = child[inner]
        rows = np.arange(len(inner))
        for used in range(2, arity):
            open_ = (slots >= 0) & ~cut[np.maximum(slots, 0)]
            weight = np.where(open_, count[np.maximum(slots, 0)], -1)
            pick = np.argmax(weight, axis=1)
            go = weight[rows, pick] >= 0
            node = slots[rows[go], pick[go]]
            slots[rows[go], pick[go]] = child[node, 0]
            slots[rows[go], used] = child[node, 1]
        # children in the order of their triangle ranges
        key = np.where(slots >= 0, first[np.maximum(slots, 0)], np.iinfo(np.int64).max)
        slots = np.take_along_axis(slots, np.argsort(key, axis=1, kind="stable"), axis=1)
        nkids = (slots >= 0).sum(axis=1)
        # final ids: this level's children follow each other in parent order
        next_ids = level_start[-1] + np.arange(nkids.sum())
        final = np.full_like(slots, -1)
        final[slots >= 0] = next_ids
        level_rows = np.full((len(frontier), arity), -1, dtype=np.int64)
        level_rows[~cut[frontier]] = final
        kid_rows.append(level_rows)
        frontier = slots[slots >= 0]
        src.append(frontier)
        level_start.append(level_start[-1] + len(frontier))
    return (np.concatenate(src), np.concatenate(kid_rows), np.array(level_start, dtype=np.int64))
