"""Sleeping islands: bodies that have come to rest stop being simulated until something
touches them.

An island is a group of dynamic bodies joined by contacts. When every body of an island has
moved slower than SLEEP_SPEED for SLEEP_FRAMES frames in a row (and none of them touches a
moving kinematic body or collider), the island falls asleep: its bodies keep their pose, have no
velocity, and weigh on others as if static. A sleeping island wakes, whole, when an awake body
faster than WAKE_SPEED or a moving kinematic body or collider touches one of its bodies.
"""
from __future__ import annotations

import numpy as np

SLEEP_SPEED = 0.01  # [m/s] of any point of the body (centre speed + |w| * bound radius)
SLEEP_FRAMES = 12  # consecutive slow frames before an island sleeps (half a second at 24 fps)
WAKE_SPEED = 0.05  # [m/s] a body touching a sleeper wakes it when at least this fast


def islands(count: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(count,) island labels of bodies joined by the edges (a, b) (connected components by
    label propagation with pointer jumping; a label is the smallest body index of its island)."""
    label = np.arange(count)
    if not len(a):
        return label
    while True:
        low = np.minimum(label[a], label[b])
        new = label.copy()
        np.minimum.at(new, a, low)
        np.minimum.at(new, b, low)
        new = new[new]  # jump to the label's label
        if np.array_equal(new, label):
            return label
        label = new


def wakers(asleep: np.ndarray, island: np.ndarray, a: np.ndarray, b: np.ndarray,
           active: np.ndarray) -> np.ndarray:
    """Bodies to wake (bool over the sleeping bodies' rows): the whole islands of sleeping
    bodies that touch an ``active`` one (an awake dynamic body or a moving posed body) through
    a contact (a, b)."""
    n = len(asleep)
    touched = []
    for sleeper, other in ((a, b), (b, a)):
        inside = sleeper < n
        s, o = sleeper[inside], other[inside]
        hit = asleep[s] & active[o]
        touched.append(s[hit])
    hit = np.concatenate(touched)
    if not len(hit):
        return np.zeros(n, bool)
    return asleep & np.isin(island, island[hit])


def update(asleep, slow, island, speed, a, b, dynamic, pinned):
    """Sleep bookkeeping at a frame's end, in place. ``speed`` (n,) point speed bound of each
    body, (a, b) this frame's contact pairs (solver rows), ``dynamic`` (n,) awake dynamic
    bodies, ``pinned`` (n,) bodies touching a moving kinematic body or collider. Returns the
    bodies that fell asleep now."""
    n = len(asleep)
    slow[:] = np.where(dynamic & (speed < SLEEP_SPEED), slow + 1, 0)
    both = (a < n) & (b < n)
    a, b = a[both], b[both]
    joined = dynamic[a] & dynamic[b]
    label = islands(n, a[joined], b[joined])
    restless = np.zeros(n, bool)
    np.logical_or.at(restless, label, dynamic & ((slow < SLEEP_FRAMES) | pinned))
    now = dynamic & ~restless[label]
    asleep[now] = True
    island[now] = label[now]
    return now
