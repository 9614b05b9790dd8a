"""The resting contact force by columns (a still ground that is not turned) against the general
route, value for value; and which surfaces take the column route."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from physanim.core.contact import ColliderFrame, ColliderPaths, ContactForce, Contacts
from physanim.core.contact import resting_contacts
from physanim.core.forces.fields import ParticleView


def _forces(axis, sign, rows):
    """Random forces, velocities and masses of 400 points; contacts on ``rows`` of them with
    the normal ``sign`` e_axis, sliding and stuck ones, some pulled off the surface."""
    rng = np.random.default_rng(7 + axis)
    n = 400
    f = rng.normal(0.0, 5.0, (n, 3))
    v = rng.normal(0.0, 1.0, (n, 3))
    v[::3] = 0.0  # at rest: static friction
    v[1::7] *= 1e-4  # barely sliding: friction stops them
    mass = rng.uniform(0.01, 2.0, n)
    normal = np.zeros((len(rows), 3))
    normal[:, axis] = sign
    mu = rng.uniform(0.0, 1.2, len(rows))
    contacts = Contacts.of(rows, rng.normal(size=(len(rows), 3)), normal,
                           np.zeros((len(rows), 3)), mu, np.full(len(rows), 0.5))
    return ParticleView(rng.normal(size=(n, 3)), v, mass, 0.0), f, contacts


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("sign", [1.0, -1.0])
@pytest.mark.parametrize("every", [True, False])
def test_the_column_route_gives_the_general_routes_forces(axis, sign, every):
    rows = np.arange(400) if every else np.sort(np.random.default_rng(1).choice(400, 150, False))
    p, f, general = _forces(axis, sign, rows)
    along = dataclasses.replace(general, axis=(axis, sign))
    expected, got = f.copy(), f.copy()
    ContactForce(general, 0.01).constrain(p, expected)
    ContactForce(along, 0.01).constrain(p, got)
    assert not np.array_equal(expected, f)  # the force did something
    np.testing.assert_array_equal(got, expected)
    fn = np.einsum("ij,ij->i", expected[rows], general.normal)
    assert np.all(fn >= -1e-12)  # nothing pushes into the surface any more
    # taking rows and merging keep the route where it holds
    assert along.take(np.arange(10)).axis == (axis, sign)
    assert along.merged(along.take(np.arange(5))).axis == (axis, sign)
    assert along.merged(general.take(np.arange(5))).axis is None


def _paths(shape, m0, m1):
    return ColliderPaths().of([ColliderFrame("Ground", shape, m0, m1, 0.5, 0.3)], 0.04)


def test_which_grounds_take_the_column_route():
    """A still ground or plane that is not turned, with every point on one side: the column
    route; a turned, moving or two-sided one: the general route, with equal results."""
    x = np.array([[0.0, 0.0, 0.001], [0.3, 0.2, -0.0005], [0.1, -0.4, 0.0002]])
    v = np.zeros((3, 3))
    turned = np.eye(4)
    turned[:3, :3] = [[1, 0, 0], [0, 0.6, -0.8], [0, 0.8, 0.6]]
    moved = np.eye(4)
    moved[2, 3] = 0.01
    big = np.diag([10.0, 10.0, 1.0, 1.0])
    cases = [("HALF_SPACE", np.eye(4), np.eye(4), (2, 1.0)),
             ("PLANE", big, big, None),  # points on both sides
             ("HALF_SPACE", turned, turned, None),
             ("HALF_SPACE", np.eye(4), moved, None)]
    for shape, m0, m1, axis in cases:
        paths = _paths(shape, m0, m1)
        got = resting_contacts(paths, x, v, 0.0, 0.1)
        assert got.axis == axis, shape
    above = x.copy()
    above[:, 2] = np.abs(above[:, 2])
    paths = _paths("PLANE", big, big)
    assert resting_contacts(paths, above, v, 0.0, 0.1).axis == (2, 1.0)
    assert resting_contacts(paths, -above, v, 0.0, 0.1).axis == (2, -1.0)
