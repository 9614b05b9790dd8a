"""Warm starting across frames: a contact found this frame takes the impulse of last frame's
contact of the same two bodies at (nearly) the same place on them.

Matching by place rather than by feature ids keeps resting contacts matched where features are
ambiguous — two aligned boxes in a stack touch corner on corner, and which box's corner a
point is named after flips with rounding. Places are kept in the frame of the pair's lower
body, so a stack that drifts or turns as a whole still matches.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import quaternion as quat

MATCH_FRACTION = 0.1  # of the smaller body's bound radius: how far a contact may have moved
MAX_PER_PAIR = 16  # contact points compared per pair (manifolds hold at most 8)


@dataclass
class Remembered:
    """Last frame's contacts, sorted by pair: pair (k,) int64 = lo * N + hi body rows,
    local (k, 3) place in the lower body's frame [m], impulse (k, 3) world [N s]."""

    pair: np.ndarray
    local: np.ndarray
    impulse: np.ndarray

    @classmethod
    def none(cls) -> Remembered:
        return cls(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)))


@dataclass
class Kept:
    """Contacts carried from one search to the next, across frames too.

    Attributes:
        contacts: the contact set (a :class:`~.contact_set.ContactSet`, anchors given at
            the poses it was left at), or None before the first frame.
        x, q: (N, 3), (N, 4) each solver body's pose when its contacts were last searched.
        names: the solver bodies' names: carried contacts hold only while the rows are the
            same bodies (colliders may come and go between frames).
    """

    contacts: object | None
    x: np.ndarray
    q: np.ndarray
    names: tuple

    @classmethod
    def none(cls) -> Kept:
        return cls(None, np.zeros((0, 3)), np.zeros((0, 4)), ())


def places(a, b, point, x, q, count: int):
    """(pair keys, places in the lower body's frame) of contact points between rows a and b."""
    lo = np.minimum(a, b)
    local = quat.rotate(quat.conjugate(q[lo]), point - x[lo])
    return lo * count + np.maximum(a, b), local


def remember(pair, local, impulse) -> Remembered:
    order = np.argsort(pair, kind="stable")
    return Remembered(pair[order], local[order], impulse[order])


def recall(memory: Remembered, pair: np.ndarray, local: np.ndarray,
           tolerance: np.ndarray) -> np.ndarray:
    """(k, 3) world impulses of last frame's nearest contacts of the same pairs within
    ``tolerance`` (k,) [m] of each new place; zeros where none is."""
    out = np.zeros((len(pair), 3))
    if not len(memory.pair) or not len(pair):
        return out
    start = np.searchsorted(memory.pair, pair, side="left")
    count = np.minimum(np.searchsorted(memory.pair, pair, side="right") - start, MAX_PER_PAIR)
    width = max(int(count.max()), 1)  # (as many slots as the fullest pair needs)
    slots = start[:, None] + np.arange(width)[None, :]
    valid = np.arange(width)[None, :] < count[:, None]
    slots = np.where(valid, slots, 0)
    dist = np.linalg.norm(memory.local[slots] - local[:, None, :], axis=2)
    dist = np.where(valid, dist, np.inf)
    best = np.argmin(dist, axis=1)
    rows = np.arange(len(pair))
    hit = dist[rows, best] <= tolerance
    out[hit] = memory.impulse[slots[rows, best]][hit]
    return out
