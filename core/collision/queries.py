"""Hierarchy against hierarchy: which triangles of two meshes, each under its own rigid transform,
overlap (collision determination), or whether any do (collision detection).

The two trees are descended simultaneously, one batch of node pairs at a time: test the pairs'
volumes, keep the overlapping ones, replace each by the pairs of its children, and send pairs of
two leaves to the exact triangle test (:func:`.tritri.triangles_overlap`). Descent rule
``"larger"`` opens the larger volume of a pair (Gottschalk), ``"both"`` opens both at once.

Frames: everything happens in mesh A's local frame (when both meshes share one transform, in
their common frame, with no mapping at all). B's vertices are mapped there once, at the first
triangle test, and B's volumes lazily, the first time each is needed (counted in n_u): exactly
for spheres and OBBs, by a conservative re-bound for AABBs and k-DOPs. Volume tests use a margin of
:data:`.bounding.PAD_REL` times the coordinates' magnitude, so rounding in those maps can never
hide a pair the triangle test would report: the result is exactly the brute-force set of
overlapping triangle pairs for the mapped coordinates.

Time-critical mode: with a :class:`~.cost.Budget`, pairs are refined breadth first (coarse to
fine) and the query stops when the budget is spent. It returns the triangle pairs confirmed so
far plus the node pairs it did not get to refine (``unresolved``); any contact not yet confirmed
lies inside one of those, so ``possible_contact`` is conservative: never False when the meshes
touch.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from ..transforms import inverse_affine, transform_points
from .bounding import PAD_REL, similarity_scale
from .bvh import BVH
from .cost import Budget, Meter, QueryCost
from .tritri import triangles_overlap

DESCENT = ("larger", "both")
BATCH = 1 << 15          # node pairs per batch (bounds memory)
BUDGET_BATCH = 1 << 10   # smaller batches when a budget is checked between them
PRIMITIVE_CHUNK = 1 << 18


@dataclass(frozen=True)
class MeshContacts:
    """Result of :func:`collide`.

    Attributes:
        pairs: (k, 2) int64 overlapping (triangle of A, triangle of B), sorted; at most one pair
            when only the first was asked for.
        unresolved: (j, 2) int64 (node of A, node of B) pairs a budget left unrefined.
        complete: False when a budget stopped the query before it finished.
        n_v, n_p, n_u: the seed's cost terms (see :mod:`.cost`).
    """

    pairs: np.ndarray
    unresolved: np.ndarray
    complete: bool
    n_v: int
    n_p: int
    n_u: int

    @property
    def hit(self) -> bool:
        """A triangle pair is confirmed to overlap."""
        return len(self.pairs) > 0

    @property
    def possible_contact(self) -> bool:
        """Conservative answer: confirmed contact, or unrefined pairs that may hold one."""
        return self.hit or len(self.unresolved) > 0

    @property
    def cost(self) -> QueryCost:
        return QueryCost(self.n_v, self.n_p, self.n_u)


def collide(a: BVH, b: BVH, matrix_a=None, matrix_b=None, *, first: bool = False,
            descend: str = "larger", budget: Budget | None = None) -> MeshContacts:
    """Overlapping triangle pairs of two meshes (determination), or the first one (detection).

    Args:
        a, b: hierarchies of the same bounding-volume kind.
        matrix_a, matrix_b: (4, 4) local-to-world transforms (rotation, translation, uniform
            scale); None for the identity.
        first: stop at the first overlapping pair (collision detection).
        descend: ``"larger"`` or ``"both"`` (see the module docstring).
        budget: time-critical mode (see the module docstring).
    """
    if a.kind.name != b.kind.name:
        raise ValueError(f"both hierarchies must use the same bounding volume "
                         f"(got {a.kind.name!r} and {b.kind.name!r})")
    if descend not in DESCENT:
        raise ValueError(f"descend must be one of {DESCENT} (got {descend!r})")
    return _Descent(a, b, matrix_a, matrix_b, first, descend, budget).run()


def collision_detection(a: BVH, b: BVH, matrix_a=None, matrix_b=None, **options) -> MeshContacts:
    """:func:`collide` stopping at the first overlapping triangle pair."""
    return collide(a, b, matrix_a, matrix_b, first=True, **options)


def collision_determination(a: BVH, b: BVH, matrix_a=None, matrix_b=None,
                            **options) -> MeshContacts:
    """:func:`collide` returning every overlapping triangle pair."""
    return collide(a, b, matrix_a, matrix_b, first=False, **options)


class _MovedVolumes:
    """B's volumes mapped into A's frame on first use (each map counts once in n_u)."""

    def __init__(self, tree: BVH, rel: np.ndarray, identity: bool):
        self.tree, self.rel, self.identity = tree, rel, identity
        self.cache = tree.node_bv if identity else np.empty_like(tree.node_bv)
        self.done = np.zeros(tree.node_count, dtype=bool)
        self.updated = 0

    def __getitem__(self, nodes: np.ndarray) -> np.ndarray:
        if not self.identity:
            need = np.unique(nodes[~self.done[nodes]])
            if len(need):
                self.cache[need] = self.tree.kind.transform(self.tree.node_bv[need], self.rel)
                self.done[need] = True
                self.updated += len(need)
        return self.cache[nodes]


class _Descent:
    """Working state of one :func:`collide` call."""

    def __init__(self, a, b, matrix_a, matrix_b, first, descend, budget):
        eye = np.eye(4)
        ma = eye if matrix_a is None else np.asarray(matrix_a, dtype=np.float64)
        mb = eye if matrix_b is None else np.asarray(matrix_b, dtype=np.float64)
        similarity_scale(ma, a.mesh.name)
        similarity_scale(mb, b.mesh.name)
        identity = bool(np.array_equal(ma, mb))  # one frame: nothing to map, nothing rounded
        rel = eye if identity else inverse_affine(ma) @ mb  # B's local frame -> A's local frame
        self.scale_b = 1.0 if identity else similarity_scale(rel, b.mesh.name)
        self.rel, self.identity = rel, identity
        # magnitude of B's coordinates in A's frame, bounded without mapping every vertex
        reach = b.mesh.scale * self.scale_b * np.sqrt(3.0) + float(np.abs(rel[:3, 3]).max())
        self.margin = PAD_REL * max(a.mesh.scale, reach, 1e-300)
        self._tri_b = None
        self.a, self.b = a, b
        self.moved = _MovedVolumes(b, rel, identity)
        self.first, self.descend, self.budget = first, descend, budget
        self.n_v = self.n_p = 0

    def run(self) -> MeshContacts:
        meter = Meter(self.budget)
        batch = BATCH if self.budget is None else BUDGET_BATCH
        queue = deque([(np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64))])
        take = queue.pop if self.budget is None else queue.popleft  # budget: breadth first
        found = []
        while queue:
            left = meter.tests_left(self.n_v + self.n_p)
            if left <= 0:
                break
            na, nb = take()
            if len(na) > left:
                queue.appendleft((na[int(left):], nb[int(left):]))
                na, nb = na[:int(left)], nb[:int(left)]
            keep = self.a.kind.overlap(self.a.node_bv[na], self.moved[nb], self.margin)
            self.n_v += len(na)
            na, nb = na[keep], nb[keep]
            leaf = self.a.node_is_leaf[na] & self.b.node_is_leaf[nb]
            if leaf.any():
                hits, rest = self._primitives(na[leaf], nb[leaf], meter)
                found.append(hits)
                if self.first and len(hits):
                    return self._result(hits[:1], [], True)
                if len(rest[0]):
                    queue.appendleft(rest)
            ca, cb = self._expand(na[~leaf], nb[~leaf])
            for s in range(0, len(ca), batch):
                queue.append((ca[s:s + batch], cb[s:s + batch]))
        pairs = np.concatenate(found) if found else np.zeros((0, 2), dtype=np.int64)
        return self._result(pairs, list(queue), not queue)

    def _result(self, pairs, queue, complete) -> MeshContacts:
        if len(pairs):
            pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
        if queue:
            unresolved = np.stack([np.concatenate([q[0] for q in queue]),
                                   np.concatenate([q[1] for q in queue])], axis=1)
        else:
            unresolved = np.zeros((0, 2), dtype=np.int64)
        return MeshContacts(pairs.reshape(-1, 2), unresolved, complete, self.n_v, self.n_p,
                            self.moved.updated)

    def _expand(self, na, nb):
        """Child pairs of internal node pairs."""
        a, b = self.a, self.b
        la, lb = a.node_is_leaf[na], b.node_is_leaf[nb]
        if self.descend == "both":
            go_a, go_b = ~la & lb, la & ~lb
            both = ~la & ~lb
        else:
            go_a = ~la & (lb | (a.node_size[na] >= self.scale_b * b.node_size[nb]))
            go_b = ~go_a
            both = np.zeros(len(na), dtype=bool)
        parts_a, parts_b = [], []
        kids = a.node_child[na[go_a]]
        real = kids >= 0
        parts_a.append(kids[real])
        parts_b.append(np.repeat(nb[go_a], real.sum(axis=1)))
        kids = b.node_child[nb[go_b]]
        real = kids >= 0
        parts_b.append(kids[real])
        parts_a.append(np.repeat(na[go_b], real.sum(axis=1)))
        if both.any():
            ka = a.node_child[na[both]][:, :, None]
            kb = b.node_child[nb[both]][:, None, :]
            ka, kb = np.broadcast_arrays(ka, kb)
            real = (ka >= 0) & (kb >= 0)
            parts_a.append(ka[real])
            parts_b.append(kb[real])
        return np.concatenate(parts_a), np.concatenate(parts_b)

    @property
    def tri_b(self) -> np.ndarray:
        """B's triangles in leaf order, in A's frame (mapped on the first primitive test)."""
        if self._tri_b is None:
            b = self.b
            vb = b.mesh.vertices if self.identity else transform_points(self.rel, b.mesh.vertices)
            self._tri_b = vb[b.mesh.triangles][b.tri_order]
        return self._tri_b

    def _primitives(self, na, nb, meter: Meter):
        """Triangle tests of leaf pairs (as many as the budget allows): (hit pairs (k, 2),
        untested leaf pairs)."""
        a, b = self.a, self.b
        ca, cb = a.node_tri_count[na], b.node_tri_count[nb]
        m = ca * cb
        left = meter.tests_left(self.n_v + self.n_p)
        if m.sum() > left:  # budget: whole leaf pairs only, the rest stays unresolved
            fit = int(np.searchsorted(np.cumsum(m), left, side="right"))
            rest = (na[fit:], nb[fit:])
            na, nb, ca, cb, m = na[:fit], nb[:fit], ca[:fit], cb[:fit], m[:fit]
        else:
            rest = (na[:0], nb[:0])
        rep = np.repeat(np.arange(len(na)), m)
        k = np.arange(m.sum()) - np.repeat(np.cumsum(m) - m, m)
        ia = a.node_first[na][rep] + k // cb[rep]
        ib = b.node_first[nb][rep] + k % cb[rep]
        hits = []
        for s in range(0, len(ia), PRIMITIVE_CHUNK):
            sa, sb = ia[s:s + PRIMITIVE_CHUNK], ib[s:s + PRIMITIVE_CHUNK]
            ok = triangles_overlap(self.a.ordered_triangles[sa], self.tri_b[sb])
            self.n_p += len(sa)
            if ok.any():
                hits.append(np.stack([a.tri_order[sa[ok]], b.tri_order[sb[ok]]], axis=1))
                if self.first:
                    break
        pairs = np.concatenate(hits) if hits else np.zeros((0, 2), dtype=np.int64)
        return pairs, rest
