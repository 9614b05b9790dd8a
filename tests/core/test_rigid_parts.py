"""The rigid bodies' small parts: quaternion algebra, contact colouring, soft constraints."""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core.rigid import quaternion as quat
from physanim.core.rigid.contact_set import colour, tangents
from physanim.core.rigid.contact_solver import Softness


def _random_q(rng, n):
    return quat.normalized(rng.normal(size=(n, 4)))


def test_quaternion_matrix_round_trip_and_rotation_agree():
    rng = np.random.default_rng(0)
    q = _random_q(rng, 500)
    r = quat.to_matrix(q)
    np.testing.assert_allclose(r @ np.swapaxes(r, 1, 2), np.broadcast_to(np.eye(3), r.shape),
                               atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-12)
    np.testing.assert_allclose(quat.from_matrix(r), q, atol=1e-12)
    v = rng.normal(size=(500, 3))
    np.testing.assert_allclose(quat.rotate(q, v), np.einsum("nij,nj->ni", r, v), atol=1e-12)
    p = _random_q(rng, 500)  # products compose rotations: R(pq) = R(p) R(q)
    np.testing.assert_allclose(quat.to_matrix(quat.multiply(p, q)), quat.to_matrix(p) @ r,
                               atol=1e-12)
    np.testing.assert_allclose(quat.multiply(q, quat.conjugate(q)),
                               np.broadcast_to([1.0, 0.0, 0.0, 0.0], q.shape), atol=1e-12)


@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-5, 0.3, 3.0])
def test_exponential_map_turns_by_the_angle_about_the_axis(angle):
    axis = np.array([1.0, -2.0, 0.5]) / math.sqrt(5.25)
    q = quat.from_rotation_vector((axis * angle)[None])
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-15)
    np.testing.assert_allclose(q[0], [math.cos(angle / 2), *(axis * math.sin(angle / 2))],
                               atol=1e-15)


def test_tangents_complete_orthonormal_bases():
    rng = np.random.default_rng(1)
    n = rng.normal(size=(1000, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    n[:3] = [[1, 0, 0], [0, 1, 0], [0, 0, -1]]
    t1, t2 = tangents(n)
    basis = np.stack([n, t1, t2], axis=1)
    np.testing.assert_allclose(basis @ np.swapaxes(basis, 1, 2),
                               np.broadcast_to(np.eye(3), basis.shape), atol=1e-12)


def test_colouring_never_puts_a_dynamic_body_twice_in_a_group():
    rng = np.random.default_rng(2)
    bodies = 60
    dynamic = rng.random(bodies) < 0.8
    a = rng.integers(0, bodies, 2000)
    b = (a + rng.integers(1, bodies, 2000)) % bodies
    groups = colour(a, b, dynamic)
    seen = np.concatenate(groups)
    assert np.array_equal(np.sort(seen), np.arange(2000))  # every contact, once
    for g in groups:
        ends = np.concatenate([a[g][dynamic[a[g]]], b[g][dynamic[b[g]]]])
        assert len(np.unique(ends)) == len(ends)
    # maximal groups: at most 2 D - 1 of them for D contacts on the busiest dynamic body
    degree = np.bincount(np.concatenate([a[dynamic[a]], b[dynamic[b]]]), minlength=bodies)
    assert len(groups) <= 2 * degree.max() - 1


def test_soft_constraint_coefficients_are_those_of_a_damped_spring():
    h = 1.0 / 240.0
    soft = Softness.of(30.0, 10.0, h)
    omega = 2 * math.pi * 30.0
    assert soft.bias_rate == pytest.approx(omega / (2 * 10.0 + h * omega))
    assert 0.0 < soft.mass_scale < 1.0 and 0.0 < soft.impulse_scale < 1.0
    assert soft.mass_scale + soft.impulse_scale == pytest.approx(1.0)
    rigid = Softness.of(0.0, 10.0, h)
    assert (rigid.bias_rate, rigid.mass_scale, rigid.impulse_scale) == (0.0, 1.0, 0.0)
