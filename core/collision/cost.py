"""The seed's cost terms, and the budget of time-critical queries.

The cost of a hierarchy query is T = n_v C_v + n_p C_p + n_u C_u: n_v bounding-volume tests
(volume-volume, or query-volume for rays and points), n_p primitive tests (triangle-triangle,
segment-triangle, point-triangle), n_u volumes updated (transformed into the other object's
frame during the query, or refitted after a deformation). Every query result carries its three
counts; :meth:`QueryCost.total` weighs them.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass


@dataclass(frozen=True)
class QueryCost:
    """Counts of the work a query did.

    Attributes:
        n_v: bounding-volume tests.
        n_p: primitive tests.
        n_u: bounding volumes updated.
    """

    n_v: int
    n_p: int
    n_u: int

    def total(self, c_v: float = 1.0, c_p: float = 1.0, c_u: float = 1.0) -> float:
        """T = n_v C_v + n_p C_p + n_u C_u for per-test costs C (e.g. measured seconds)."""
        return self.n_v * c_v + self.n_p * c_p + self.n_u * c_u


@dataclass(frozen=True)
class Budget:
    """Limits of a time-critical query; it stops refining at whichever comes first.

    Args:
        max_tests: largest n_v + n_p (None: unlimited).
        seconds: wall-clock limit [s] (None: unlimited). Checked between batches of tests, so a
            query may overrun it by one batch.
    """

    max_tests: int | None = None
    seconds: float | None = None

    def __post_init__(self):
        if self.max_tests is not None and (int(self.max_tests) != self.max_tests
                                           or self.max_tests < 0):
            raise ValueError(f"budget max_tests must be an integer >= 0 (got {self.max_tests})")
        if self.seconds is not None and not (math.isfinite(self.seconds) and self.seconds >= 0):
            raise ValueError(f"budget seconds must be finite and >= 0 (got {self.seconds})")

    def meter(self) -> Meter:
        return Meter(self)


class Meter:
    """A running budget: how many tests are left now."""

    def __init__(self, budget: Budget | None):
        self.budget = budget
        self.start = time.perf_counter()

    def tests_left(self, used: int) -> float:
        """Tests still allowed after ``used`` (0 once the time is up; inf without limits)."""
        b = self.budget
        if b is None:
            return math.inf
        if b.seconds is not None and time.perf_counter() - self.start >= b.seconds:
            return 0
        if b.max_tests is None:
            return math.inf
        return max(b.max_tests - used, 0)
