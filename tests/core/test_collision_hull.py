"""Quickhull: closed, outward, convex hulls that contain every point, robust to duplicate and
coplanar points; lower-dimensional inputs give flat hulls, segments and points."""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.collision import convex_hull


def _check_closed_convex(hull, points):
    tri = hull.triangles
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    directed = set(map(tuple, edges.tolist()))
    assert len(directed) == len(edges), "each directed edge once"
    assert all((b, a) in directed for a, b in directed), "closed: every edge has its twin"
    assert len(hull.vertices) - len(edges) // 2 + len(tri) == 2, "Euler characteristic"
    t = hull.points[tri]
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    height = points @ n.T - np.einsum("ij,ij->i", n, t[:, 0])
    assert height.max() <= 10 * hull.tolerance, "every point inside every face plane"
    centre = points.mean(axis=0)
    assert np.all(np.einsum("ij,ij->i", n, t.mean(axis=1) - centre) > 0), "outward"


@pytest.mark.parametrize("shape", ["gauss", "sphere", "cube-grid", "cube-faces", "integers"])
def test_hulls_are_closed_convex_and_contain_the_points(shape):
    rng = np.random.default_rng(0)
    if shape == "gauss":
        p = rng.normal(size=(3000, 3)) * [3, 1, 0.2]
    elif shape == "sphere":
        p = rng.normal(size=(2000, 3))
        p /= np.linalg.norm(p, axis=1, keepdims=True)
    elif shape == "cube-grid":  # coplanar points on every face, every point three times
        g = np.stack(np.meshgrid(*[np.linspace(-1, 1, 7)] * 3), -1).reshape(-1, 3)
        p = np.concatenate([g, g, g])
    elif shape == "cube-faces":
        p = rng.uniform(-1, 1, (3000, 3))
        p[np.arange(3000), rng.integers(0, 3, 3000)] = rng.choice([-1.0, 1.0], 3000)
    else:
        p = rng.integers(0, 3, (400, 3)).astype(float)
    hull = convex_hull(p)
    assert hull.dimension == 3
    _check_closed_convex(hull, p)
    if shape == "cube-grid":
        assert hull.volume == pytest.approx(8.0, rel=1e-12)
        assert len(hull.vertices) == 8
    if shape == "sphere":
        assert len(hull.vertices) == len(p)  # every point is a corner
        assert hull.volume == pytest.approx(4 / 3 * np.pi, rel=0.01)


def test_flat_hull_is_a_fan_over_the_polygon():
    rng = np.random.default_rng(1)
    xy = rng.normal(size=(200, 2))
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    p = np.c_[xy, np.full(200, 0.5)] @ rot.T
    hull = convex_hull(p)
    assert hull.dimension == 2 and hull.volume == 0.0
    # area equals the 2D hull's (shoelace over the hull's corners in angular order)
    c = xy[hull.vertices]
    order = np.argsort(np.arctan2(*(c - c.mean(0)).T[::-1]))
    x, y = c[order].T
    shoelace = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    assert hull.area == pytest.approx(shoelace, rel=1e-9)
