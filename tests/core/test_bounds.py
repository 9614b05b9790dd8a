"""State bounds: a point outside the world bound, faster than the speed limit, or non-finite is
found and described with its value and the bound; bad bounds are refused."""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core.bounds import StateBounds


def test_points_inside_the_bounds_pass():
    b = StateBounds(position=10.0, speed=5.0)
    x = np.array([[9.99, -10.0, 0.0], [0.0, 0.0, 0.0]])
    v = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, -4.99]])  # |v| = 5 exactly is allowed
    assert b.violation(x, v) is None
    assert b.violation(np.zeros((0, 3)), np.zeros((0, 3))) is None


@pytest.mark.parametrize("x, v, index, words", [
    ([[0, 0, 0], [0, 0, 10.5]], [[0, 0, 0], [0, 0, 0]], 1, ["position", "10.5", "world bound (±10 m)"]),
    ([[0, 0, 0], [0, 0, 0]], [[0, 0, 0], [3, 4, 0.1]], 1, ["speed 5.001 m/s", "speed limit (5 m/s)"]),
    ([[0, 0, math.nan], [0, 0, 0]], [[0, 0, 0], [0, 0, 0]], 0, ["position became", "nan"]),
    ([[0, 0, 0], [0, 0, 0]], [[0, 0, 0], [math.inf, 0, 0]], 1, ["velocity became", "inf"]),
    ([[0, 0, 0]], [[1e300, 1e300, 0]], 0, ["speed 1.414e+300 m/s"]),
])
def test_the_first_point_outside_is_named_with_its_value(x, v, index, words):
    found = StateBounds(position=10.0, speed=5.0).violation(np.array(x, float), np.array(v, float))
    assert found is not None and found[0] == index
    for w in words:
        assert w in found[1], found[1]


@pytest.mark.parametrize("bad", [0.0, -1.0, math.inf, math.nan])
def test_bounds_must_be_finite_and_positive(bad):
    with pytest.raises(ValueError, match="bound must be finite and > 0"):
        StateBounds(position=bad)
    with pytest.raises(ValueError, match="bound must be finite and > 0"):
        StateBounds(speed=bad)


def test_points_are_judged_as_by_their_definition_near_the_bounds():
    """Coordinates and speeds scattered around both bounds (the quick test by components and the
    exact one by speeds must agree with the definition: every |x_k| <= position, every
    |v| <= speed)."""
    rng = np.random.default_rng(3)
    b = StateBounds(position=10.0, speed=5.0)
    for _ in range(400):
        n = int(rng.integers(1, 6))
        x = rng.uniform(-10.2, 10.2, (n, 3)) * rng.choice([0.5, 1.0], (n, 1))
        v = rng.normal(0.0, 1.0, (n, 3))
        v *= rng.uniform(2.0, 5.2, (n, 1)) / np.linalg.norm(v, axis=1, keepdims=True)
        inside = bool((np.abs(x) <= 10.0).all() and (np.einsum("ij,ij->i", v, v) <= 25.0).all())
        assert (b.violation(x, v) is None) == inside
        assert inside or not b.within(x, v)  # the quick test never passes a point outside
        if (np.abs(v) <= 5.0 / math.sqrt(3.0) * (1.0 - 1e-9)).all():
            assert b.within(x, v) == inside  # nor fails one whose components are small
