"""Broad phase: which of n axis-aligned boxes overlap (the seed's "Two-level CD").

Every broad phase is a class with one method, ``pairs(lo, hi) -> (m, 2) int64``, and a
``last_stats`` attribute describing the last call's cost, so they are interchangeable:

==================================  ===========================================================
:class:`AllPairs`                   every pair tested, n (n - 1) / 2 tests: the reference
:class:`SweepAndPrune`              sorted endpoints on 1, 2 or 3 axes, coherent between frames
:class:`UniformGrid`                uniform grid / spatial hash of cubic cells
:class:`Octree`                     adaptive linear octree, built level by level
==================================  ===========================================================

Conventions (the same for all, so they return identical arrays):

* A box is the closed interval ``[lo, hi]`` on each axis: boxes touching at a face, edge or
  corner overlap, and so does a zero-size box lying on another box's boundary.
* Pairs are ``(i, j)`` with ``i < j``, unique, sorted lexicographically.
* A non-finite bound or ``lo > hi`` raises :class:`~physanim.core.errors.PhysanimError` (a
  ValueError) naming the box index and its values.

Box policies (the two the seed compares). A broad phase takes boxes; what box an object gets is
the caller's choice:

* fixed-size cubes, :func:`cube_boxes`: a cube of half-side r around the object's centre, r
  the radius of its bounding sphere, holds the object in every orientation, so a rotating
  object's box only translates and is never recomputed from the geometry;
* dynamic AABBs, :func:`aabb_of_points` (any shape, from its world-space vertices) and
  :func:`aabb_of_oriented_boxes` (boxes, exactly and cheaply): tight every frame, so fewer
  false candidates, at the price of recomputing the bounds.

Every class checks its input and canonicalises its output the same way (``BroadPhase.pairs``);
temporary memory is bounded by enumerating candidates in batches (``PAIR_CHUNK``).
"""
from __future__ import annotations

import numpy as np

from ..errors import PhysanimError
from .broadphase_base import (PAIR_CHUNK, BroadPhase, BroadPhaseStats, canonical_pairs,
                              check_boxes)
from .broadphase_grid import GridStats, TooManyCandidates, UniformGrid
from .broadphase_octree import MAX_OCTREE_DEPTH, Octree, OctreeStats
from .broadphase_sap import SweepAndPrune, SweepStats, count_inversions

__all__ = [
    "AllPairs", "BroadPhase", "BroadPhaseStats", "GridStats", "MAX_OCTREE_DEPTH", "Octree",
    "OctreeStats", "PAIR_CHUNK", "SweepAndPrune", "SweepStats", "TooManyCandidates", "UniformGrid",
    "aabb_of_oriented_boxes", "aabb_of_points", "canonical_pairs", "check_boxes",
    "count_inversions", "cube_boxes",
]


class AllPairs(BroadPhase):
    """Tests every pair: the O(n^2) reference the other broad phases must match exactly.

    Vectorised over blocks of rows, each block compared with all later boxes at once; a block
    holds about ``PAIR_CHUNK`` pairs, which bounds memory.
    """

    def _find_pairs(self, lo, hi):
        n = len(lo)
        lo_t = np.ascontiguousarray(lo.T)
        hi_t = np.ascontiguousarray(hi.T)
        rows = max(1, PAIR_CHUNK // max(n, 1))
        found_i, found_j = [], []
        for start in range(0, max(n - 1, 0), rows):  # one pass per block of rows
            stop = min(start + rows, n - 1)
            r = np.arange(start, stop)
            hit = r[:, None] < np.arange(start + 1, n)[None, :]  # columns j > i only
            for a in range(3):
                la, ha = lo_t[a], hi_t[a]
                hit &= la[start:stop, None] <= ha[None, start + 1:]
                hit &= la[None, start + 1:] <= ha[start:stop, None]
            i, j = np.nonzero(hit)
            found_i.append(i + start)
            found_j.append(j + start + 1)
        i = np.concatenate(found_i) if found_i else np.empty(0, dtype=np.int64)
        j = np.concatenate(found_j) if found_j else np.empty(0, dtype=np.int64)
        return i, j, BroadPhaseStats(n, n * (n - 1) // 2, len(i))

    def __repr__(self) -> str:
        return "AllPairs()"


def cube_boxes(centres: np.ndarray, radius) -> tuple[np.ndarray, np.ndarray]:
    """Fixed-size cube policy: the cube of half-side ``radius`` centred on each object.

    With ``radius`` the object's bounding-sphere radius about ``centres``, the cube contains
    the object whatever its orientation, so only the centre moves it.

    Args:
        centres: (n, 3) object centres [m].
        radius: (n,) or scalar bounding radius [m], finite and >= 0.

    Returns:
        ``(lo, hi)``, each (n, 3) [m].
    """
    centres = np.asarray(centres, dtype=np.float64)
    if centres.ndim != 2 or centres.shape[1:] != (3,):
        raise PhysanimError(f"centres must have shape (n, 3) (got {centres.shape})")
    radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), centres.shape[:1])
    bad = ~(np.isfinite(radius) & (radius >= 0))
    if bad.any():
        k = int(np.argmax(bad))
        raise PhysanimError(
            f"radius of object {k} must be finite and >= 0 (got {float(radius[k])!r})")
    r = radius[:, None]
    return centres - r, centres + r


def aabb_of_points(points: np.ndarray, owner: np.ndarray, count: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Dynamic AABB policy: each object's exact box around its world-space points.

    Args:
        points: (m, 3) world-space vertices of all objects [m].
        owner: (m,) int, the object index 0 .. count - 1 of each point.
        count: number of objects; each must own at least one point.

    Returns:
        ``(lo, hi)``, each (count, 3) [m].
    """
    points = np.asarray(points, dtype=np.float64)
    owner = np.asarray(owner)
    if points.ndim != 2 or points.shape[1:] != (3,) or owner.shape != points.shape[:1]:
        raise PhysanimError(
            f"points must be (m, 3) with one owner each (got {points.shape} and {owner.shape})")
    if owner.size and (owner.min() < 0 or owner.max() >= count):
        raise PhysanimError(f"point owners must lie in 0..{count - 1} "
                            f"(got {int(owner.min())}..{int(owner.max())})")
    per_object = np.bincount(owner.astype(np.int64), minlength=count)
    if count and not per_object.all():
        raise PhysanimError(f"object {int(np.argmin(per_object))} owns no points: its box is "
                            "undefined")
    if count == 0:
        return np.empty((0, 3)), np.empty((0, 3))
    order = np.argsort(owner, kind="stable")
    starts = np.cumsum(per_object) - per_object
    grouped = points[order]
    return np.minimum.reduceat(grouped, starts), np.maximum.reduceat(grouped, starts)


def aabb_of_oriented_boxes(centres: np.ndarray, rotations: np.ndarray, half_extents: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray]:
    """Dynamic AABB policy for boxes: the exact AABB of each oriented box.

    Its half-size along world axis a is ``sum_b |R[a, b]| h[b]``.

    Args:
        centres: (n, 3) box centres [m].
        rotations: (n, 3, 3) rotation matrices, local -> world.
        half_extents: (n, 3) half sizes along the box's own axes [m].

    Returns:
        ``(lo, hi)``, each (n, 3) [m].
    """
    centres = np.asarray(centres, dtype=np.float64)
    rotations = np.asarray(rotations, dtype=np.float64)
    half_extents = np.asarray(half_extents, dtype=np.float64)
    n = len(centres)
    if (centres.shape != (n, 3) or rotations.shape != (n, 3, 3)
            or half_extents.shape != (n, 3)):
        raise PhysanimError(
            "oriented boxes need centres (n, 3), rotations (n, 3, 3) and half_extents (n, 3) "
            f"(got {centres.shape}, {rotations.shape} and {half_extents.shape})")
    half = np.einsum("nab,nb->na", np.abs(rotations), half_extents)
    return centres - half, centres + half
