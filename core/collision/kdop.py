"""k-DOPs (discrete oriented polytopes), of which the AABB is the 6-DOP.

A k-DOP is the intersection of k/2 slabs ``lo_i <= d_i . x <= hi_i`` with fixed directions d_i:
k = 6 the coordinate axes (an axis-aligned bounding box), 14 adds the 4 cube diagonals, 18 the 6
face diagonals, 26 both. Directions are small integer vectors (not normalised) so projections
stay cheap; every distance is converted with |d_i|.

Layout: (n, k) rows ``[lo_0 .. lo_{k/2-1}, hi_0 .. hi_{k/2-1}]`` (AABB: ``[min xyz, max xyz]``).

The overlap test is the seed's: two k-DOPs overlap when all k/2 pairs of intervals overlap.
That is exact for the intervals but only conservative for the polytopes (two disjoint DOPs may
overlap on every one of their own directions), which a hierarchy handles by descending further.

A rotated k-DOP is no longer a k-DOP. :meth:`KDOP.transform` bounds it conservatively: for each
direction it takes the smallest support among parallelepipeds made of triples of the DOP's own
slabs (each contains the DOP). For the AABB that is Arvo's |A| h bound, and for the identity map
it gives the DOP back exactly.
"""
from __future__ import annotations

from itertools import combinations

import numpy as np

from .bounding import BoundingVolume, Groups, box_axes_by_extent, linear_part, slab_interval

_AXES = [(1, 0, 0), (0, 1, 0), (0, 0, 1)]
_CORNERS = [(1, 1, 1), (1, 1, -1), (1, -1, 1), (-1, 1, 1)]
_EDGES = [(1, 1, 0), (1, 0, 1), (0, 1, 1), (1, -1, 0), (1, 0, -1), (0, 1, -1)]
FAMILIES = {6: (_AXES,), 14: (_AXES, _CORNERS), 18: (_AXES, _EDGES),
            26: (_AXES, _CORNERS, _EDGES)}


class KDOP(BoundingVolume):
    """k-DOP with k in (6, 14, 18, 26); ``KDOP(6)`` is the AABB (named ``"aabb"``)."""

    def __init__(self, k: int = 6, name: str | None = None):
        if k not in FAMILIES:
            raise ValueError(f"k-DOP k must be one of {sorted(FAMILIES)} (got {k})")
        self.k = k
        self.half = k // 2
        self.width = k
        self.name = name or f"kdop{k}"
        families = FAMILIES[k]
        self.directions = np.array([d for fam in families for d in fam], dtype=np.float64)
        self.norms = np.linalg.norm(self.directions, axis=1)
        self.is_box = k == 6  # an axis-aligned box: the layout is [lo (3), hi (3)]
        # parallelepipeds bounding the DOP for transforms: independent triples within a family
        triples, start = [], 0
        for fam in families:
            for t in combinations(range(start, start + len(fam)), 3):
                if abs(np.linalg.det(self.directions[list(t)])) > 0.5:
                    triples.append(t)
            start += len(fam)
        self.triples = np.array(triples, dtype=np.int64)
        self._triple_inv = np.linalg.inv(self.directions[self.triples])  # (t, 3, 3)
        for a in (self.directions, self.norms, self.triples, self._triple_inv):
            a.setflags(write=False)  # shared by every user of this kind

    # --- fitting ---------------------------------------------------------------------------
    def project(self, points: np.ndarray) -> np.ndarray:
        """(m, k/2) projections of points on the DOP's directions."""
        if self.is_box:
            return points
        return points @ self.directions.T

    def fit_groups(self, groups: Groups) -> np.ndarray:
        proj = self.project(groups.points)
        return np.concatenate([groups.reduce(np.minimum, proj),
                               groups.reduce(np.maximum, proj)], axis=1)

    # --- tests -----------------------------------------------------------------------------
    def overlap(self, a, b, margin=0.0):
        h = self.half
        m = margin * self.norms
        return np.all((a[:, :h] - m <= b[:, h:]) & (b[:, :h] - m <= a[:, h:]), axis=1)

    def ray_interval(self, bv, origin, direction, margin=0.0):
        h = self.half
        m = margin * self.norms
        return slab_interval(bv[:, :h] - m, bv[:, h:] + m, self.project(origin),
                             self.project(direction))

    def distance_bound(self, bv, points):
        h = self.half
        p = self.project(points)
        gap = np.maximum(np.maximum(bv[:, :h] - p, p - bv[:, h:]), 0.0) / self.norms
        if self.is_box:
            return np.sqrt(np.einsum("ij,ij->i", gap, gap))
        return gap.max(axis=1)

    def contains(self, bv, points, margin=0.0):
        h = self.half
        p = self.project(points)
        m = margin * self.norms
        return np.all((p >= bv[:, :h] - m) & (p <= bv[:, h:] + m), axis=1)

    # --- construction helpers --------------------------------------------------------------
    def transform(self, bv, matrix):
        a, t = linear_part(matrix)
        bv = np.asarray(bv, dtype=np.float64)
        h = self.half
        d = self.directions
        shift = d @ t
        # alpha[tau, i] = coordinates of A^T d_i in the basis of triple tau's directions
        alpha = np.einsum("tkj,ij->tik", self._triple_inv.transpose(0, 2, 1), d @ a)
        pos, neg = np.maximum(alpha, 0.0), np.maximum(-alpha, 0.0)
        lo_t = bv[:, self.triples]            # (n, t, 3)
        hi_t = bv[:, h + self.triples]
        up = np.einsum("ntk,tik->nti", hi_t, pos) - np.einsum("ntk,tik->nti", lo_t, neg)
        down = np.einsum("ntk,tik->nti", hi_t, neg) - np.einsum("ntk,tik->nti", lo_t, pos)
        return np.concatenate([shift - down.min(axis=1), shift + up.min(axis=1)], axis=1)

    def merge(self, a, b):
        h = self.half
        return np.concatenate([np.minimum(a[:, :h], b[:, :h]), np.maximum(a[:, h:], b[:, h:])],
                              axis=1)

    def measure(self, bv, pad):
        """Volume of the DOP's bounding box (its first three slabs) grown by ``pad``: exact for
        the AABB, an upper bound for k > 6."""
        h = self.half
        return np.prod(bv[:, h:h + 3] - bv[:, :3] + pad, axis=1)

    def size(self, bv):
        h = self.half
        e = bv[:, h:h + 3] - bv[:, :3]
        return np.sqrt(np.einsum("ij,ij->i", e, e))

    def box(self, bv) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) of the bounding box (the first three slabs), each (n, 3)."""
        h = self.half
        return bv[:, :3], bv[:, h:h + 3]

    def split_frame(self, tri, starts, counts):
        if not self.is_box:
            return super().split_frame(tri, starts, counts)
        bv = self.fit_triangles(tri, starts, counts)
        return box_axes_by_extent(bv[:, :3], bv[:, 3:])


AABB = KDOP(6, name="aabb")
