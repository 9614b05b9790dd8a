"""Sleeping islands' bookkeeping: islands by contact, who wakes, who sleeps."""
from __future__ import annotations

import numpy as np

from physanim.core.rigid import sleep


def test_islands_are_the_connected_components():
    label = sleep.islands(7, np.array([0, 1, 4, 5]), np.array([1, 2, 5, 6]))
    assert label.tolist() == [0, 0, 0, 3, 4, 4, 4]


def test_a_touched_sleeper_wakes_its_whole_island_and_no_other():
    asleep = np.array([True, True, True, False, True])
    island = np.array([0, 0, 2, -1, 4])
    woken = sleep.wakers(asleep, island, np.array([3]), np.array([1]), np.array([0, 0, 0, 1, 0],
                                                                                bool))
    assert woken.tolist() == [True, True, False, False, False]


def test_an_island_sleeps_only_when_all_its_bodies_have_rested_long_enough():
    n = 4
    asleep, slow, island = np.zeros(n, bool), np.zeros(n, np.int64), np.full(n, -1)
    dynamic = np.ones(n, bool)
    a, b = np.array([0, 2]), np.array([1, 3])  # islands {0, 1} and {2, 3}
    speed = np.array([0.0, 0.0, 0.0, 1.0])  # body 3 still moves
    for _ in range(sleep.SLEEP_FRAMES):
        sleep.update(asleep, slow, island, speed, a, b, dynamic & ~asleep, np.zeros(n, bool))
    assert asleep.tolist() == [True, True, False, False]
    assert island[:2].tolist() == [0, 0]
