"""Incremental hierarchy building: insert triangles one at a time where they cost least.

Goldsmith & Salmon's insertion (1987), with volume as the cost: a new triangle (its volume p)
either becomes the sibling of some node N — a new parent over N and p — or goes further down.
Placing it at N grows every ancestor of N to include p and adds the new parent's volume, so the
increase in total volume of the tree is

    cost(N) = sum over ancestors A of N of [measure(A + p) - measure(A)] + measure(N + p).

The insertion descends from the root, always into the child whose volume grows least, keeps the
cheapest N seen on the way, and stops when the growth already inherited exceeds that best cost
(nothing deeper can be cheaper). Volumes are the kind's own (:meth:`merge`, :meth:`measure` with
the bottom-up builder's flat-geometry pad); the final volumes are refitted from the triangles.

Each insertion depends on the tree the previous ones left, so this builder is a Python loop over
triangles (each step a few tiny array operations over one tree path): O(n log n) steps, meant
for moderate meshes and for growing a hierarchy as triangles arrive. Triangles are inserted in a
random order (``seed``) unless ``order`` is given: sorted input would build a lopsided tree.
"""
from __future__ import annotations

import numpy as np

from .bounding import BoundingVolume
from .build_bottomup import FLAT_PAD
from .build_topdown import check_shape_options
from .bvh import BVH, Topology, assemble
from .kinds import bounding_volume
from .mesh import TriangleMesh


def build_incremental(mesh: TriangleMesh, kind: str | BoundingVolume = "obb", *,
                      arity: int = 2, leaf_size: int = 4, order=None, seed: int = 0) -> BVH:
    """Hierarchy built by inserting ``mesh``'s triangles one by one.

    Args:
        mesh: the triangles.
        kind: bounding-volume kind or its name.
        arity: children per node (2 = binary; larger collapses the binary tree).
        leaf_size: maximum triangles per leaf (small subtrees become leaves).
        order: (n_tri,) insertion order (a permutation of the triangle ids), or None for a
            random permutation from ``seed``.
    """
    kind = bounding_volume(kind)
    check_shape_options(arity, leaf_size)
    tri = mesh.triangle_vertices
    n = len(tri)
    if order is None:
        order = np.random.default_rng(seed).permutation(n)
    order = np.asarray(order, dtype=np.int64)
    if order.shape != (n,) or not np.array_equal(np.sort(order), np.arange(n)):
        raise ValueError(f"insertion order must be a permutation of the {n} triangle ids")
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    pad = FLAT_PAD * max(float(np.linalg.norm(hi - lo)), 1e-300)
    tree = _Tree(kind, kind.fit_triangles(tri, np.arange(n), np.ones(n, dtype=np.int64)), pad)
    tree.root = int(order[0])
    for t in order[1:]:
        tree.insert(int(t))
    leaf_first = np.where(np.arange(2 * n - 1) < n, np.arange(2 * n - 1), 0)
    leaf_count = (np.arange(2 * n - 1) < n).astype(np.int64)
    topo = Topology(tree.child, leaf_first, leaf_count, np.arange(n, dtype=np.int64), tree.root)
    return assemble(mesh, kind, topo, arity=arity, leaf_size=leaf_size, builder="incremental")


class _Tree:
    """Binary tree under construction: nodes 0..n-1 are the triangles, n.. the inner nodes."""

    def __init__(self, kind: BoundingVolume, leaf_bv: np.ndarray, pad: float):
        n = len(leaf_bv)
        self.kind = kind
        self.pad = pad
        self.bv = np.concatenate([leaf_bv, np.zeros((max(n - 1, 0), kind.width))])
        self.measure = np.concatenate([kind.measure(leaf_bv, pad), np.zeros(max(n - 1, 0))])
        self.child = np.full((2 * n - 1, 2), -1, dtype=np.int64)
        self.parent = np.full(2 * n - 1, -1, dtype=np.int64)
        self.next_id = n
        self.root = 0

    def insert(self, leaf: int) -> None:
        kind, pad = self.kind, self.pad
        p = self.bv[leaf:leaf + 1]
        node, inherited = self.root, 0.0
        grown = kind.measure(kind.merge(self.bv[node:node + 1], p), pad)[0]
        best, best_cost = node, np.inf
        while True:
            if inherited + grown < best_cost:
                best, best_cost = node, inherited + grown
            if self.child[node, 0] < 0:
                break
            inherited += grown - self.measure[node]
            if inherited >= best_cost:
                break
            kids = self.child[node]
            merged = kind.measure(kind.merge(self.bv[kids], np.repeat(p, 2, 0)), pad)
            k = int(np.argmin(merged - self.measure[kids]))
            node, grown = int(kids[k]), merged[k]
        self._attach(best, leaf)

    def _attach(self, sibling: int, leaf: int) -> None:
        new = self.next_id
        self.next_id += 1
        up = self.parent[sibling]
        self.child[new] = (sibling, leaf)
        self.parent[[sibling, leaf]] = new
        self.parent[new] = up
        if up < 0:
            self.root = new
        else:
            self.child[up, int(self.child[up, 1] == sibling)] = new
        path = [new]
        while up >= 0:
            path.append(int(up))
            up = self.parent[up]
        path = np.array(path)
        grown = self.kind.merge(self.bv[np.where(path == new, sibling, path)],
                                np.repeat(self.bv[leaf:leaf + 1], len(path), 0))
        self.bv[path] = grown
        self.measure[path] = self.kind.measure(grown, self.pad)
