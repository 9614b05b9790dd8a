"""Bounding spheres.

Layout: (n, 4) rows ``[centre x, y, z, radius]``.

The fit tries two centres per group — the centre of the bounding box and the centroid — and
keeps whichever needs the smaller radius (the radius being the largest distance to a point).
Neither is the minimal sphere, but both are one pass of vectorised reductions.
"""
from __future__ import annotations

import numpy as np

from .bounding import BoundingVolume, Groups, linear_part

_GROW = 1.0 + 4.0 * 2.0 ** -52  # radii absorb the rounding of the distances they came from


class Sphere(BoundingVolume):
    name = "sphere"
    width = 4

    def fit_groups(self, groups: Groups) -> np.ndarray:
        p = groups.points
        lo = groups.reduce(np.minimum, p)
        hi = groups.reduce(np.maximum, p)
        best = None
        for centre in (0.5 * (lo + hi), groups.reduce(np.add, p) / groups.counts[:, None]):
            d = p - groups.spread(centre)
            r = np.sqrt(groups.reduce(np.maximum, np.einsum("ij,ij->i", d, d))) * _GROW
            cand = np.concatenate([centre, r[:, None]], axis=1)
            best = cand if best is None else np.where((r < best[:, 3])[:, None], cand, best)
        return best

    def overlap(self, a, b, margin=0.0):
        d = a[:, :3] - b[:, :3]
        reach = a[:, 3] + b[:, 3] + margin
        return np.einsum("ij,ij->i", d, d) <= reach * reach

    def transform(self, bv, matrix):
        a, t = linear_part(matrix)
        bv = np.asarray(bv, dtype=np.float64)
        stretch = np.linalg.norm(a, 2) * _GROW  # largest singular value: any linear map
        centre = bv[:, :3] @ a.T + t
        return np.concatenate([centre, bv[:, 3:] * stretch], axis=1)

    def merge(self, a, b):
        d = b[:, :3] - a[:, :3]
        dist = np.sqrt(np.einsum("ij,ij->i", d, d))
        ra, rb = a[:, 3], b[:, 3]
        radius = 0.5 * (dist + ra + rb)
        safe = np.where(dist > 0.0, dist, 1.0)
        centre = a[:, :3] + ((radius - ra) / safe)[:, None] * d
        out = np.concatenate([centre, (radius * _GROW)[:, None]], axis=1)
        out = np.where((dist + rb <= ra)[:, None], a, out)  # one already holds the other
        return np.where((dist + ra <= rb)[:, None], b, out)

    def measure(self, bv, pad):
        return (4.0 / 3.0 * np.pi) * (bv[:, 3] + pad) ** 3

    def size(self, bv):
        return 2.0 * bv[:, 3]

    def ray_interval(self, bv, origin, direction, margin=0.0):
        oc = origin - bv[:, :3]
        r = bv[:, 3] + margin
        a = np.einsum("ij,ij->i", direction, direction)
        b = np.einsum("ij,ij->i", oc, direction)
        c = np.einsum("ij,ij->i", oc, oc) - r * r
        disc = b * b - a * c
        hit = disc >= 0.0
        moving = a > 0.0
        root = np.sqrt(np.where(hit, disc, 0.0))
        safe = np.where(moving, a, 1.0)
        t0 = np.where(moving, (-b - root) / safe, np.where(c <= 0.0, -np.inf, np.inf))
        t1 = np.where(moving, (-b + root) / safe, np.where(c <= 0.0, np.inf, -np.inf))
        miss = moving & ~hit
        return np.where(miss, np.inf, t0), np.where(miss, -np.inf, t1)

    def distance_bound(self, bv, points):
        d = points - bv[:, :3]
        return np.maximum(np.sqrt(np.einsum("ij,ij->i", d, d)) - bv[:, 3], 0.0)
