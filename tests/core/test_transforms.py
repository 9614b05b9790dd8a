"""Affine transforms: decompose/compose, slerp, and the interpolated TransformPath."""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core.transforms import (
    TransformPath, column_max, column_min, compose, cross, decompose, matrix_to_quaternion,
    quaternion_to_matrix, row_all, row_any, row_max, slerp, transform_points,
)


def _axis_angle_quat(axis, angle):
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    return np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * a])


def _quat_angle(q0, q1):
    """Rotation angle between two unit quaternions [rad]."""
    return 2.0 * math.acos(min(1.0, abs(float(np.dot(q0, q1)))))


def _random_trs(rng, mirror=False):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    scale = rng.uniform(0.2, 3.0, size=3)
    if mirror:
        scale[rng.integers(3)] *= -1.0
    return compose(rng.normal(size=3) * 5, q, scale), q, scale


@pytest.mark.parametrize("mirror", [False, True])
def test_decompose_compose_round_trip(mirror):
    rng = np.random.default_rng(1)
    for _ in range(50):
        m, q, scale = _random_trs(rng, mirror)
        t, q2, s2 = decompose(m)
        np.testing.assert_allclose(compose(t, q2, s2), m, atol=1e-12)
        np.testing.assert_allclose(t, m[:3, 3])
        assert abs(np.linalg.norm(q2) - 1.0) < 1e-12
        np.testing.assert_allclose(np.abs(s2), np.abs(scale), rtol=1e-12)
        if not mirror:  # same rotation (q and -q are the same rotation)
            assert abs(abs(np.dot(q, q2)) - 1.0) < 1e-12


def test_quaternion_matrix_round_trip_all_branches():
    # Shepperd's method branches on the largest diagonal term: cover each with 180 degree turns
    # about x, y, z (trace -1) and a generic rotation.
    for axis, angle in (([1, 0, 0], math.pi), ([0, 1, 0], math.pi), ([0, 0, 1], math.pi),
                        ([1, 2, 3], 0.7), ([1, 1, 0], 3.0)):
        q = _axis_angle_quat(axis, angle)
        r = quaternion_to_matrix(q)
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
        q2 = matrix_to_quaternion(r)
        assert abs(abs(np.dot(q, q2)) - 1.0) < 1e-12


def test_slerp_endpoints_and_shortest_arc():
    q0 = _axis_angle_quat([0, 0, 1], 0.3)
    q1 = _axis_angle_quat([1, 1, 0], 2.0)
    np.testing.assert_allclose(slerp(q0, q1, 0.0), q0, atol=1e-12)
    np.testing.assert_allclose(slerp(q0, q1, 1.0), q1, atol=1e-12)
    # -q1 is the same rotation: slerp takes the shorter arc and ends on that rotation
    mid_a = slerp(q0, q1, 0.5)
    mid_b = slerp(q0, -q1, 0.5)
    assert abs(abs(np.dot(mid_a, mid_b)) - 1.0) < 1e-12
    assert abs(abs(np.dot(slerp(q0, -q1, 1.0), q1)) - 1.0) < 1e-12


@pytest.mark.parametrize("angle", [0.5, 2.0, 3.0])
def test_slerp_constant_angular_speed(angle):
    # The rotation angle from q0 grows linearly in s: s * angle (within rounding).
    q0 = _axis_angle_quat([1, -2, 0.5], 0.4)
    q1 = _quat_mul(_axis_angle_quat([0.3, 0.2, 1.0], angle), q0)
    s = np.linspace(0.0, 1.0, 21)
    qs = slerp(q0, q1, s)
    assert qs.shape == (21, 4)
    np.testing.assert_allclose(np.linalg.norm(qs, axis=1), 1.0, atol=1e-12)
    angles = [_quat_angle(q0, q) for q in qs]
    np.testing.assert_allclose(angles, s * angle, atol=1e-7)


def test_slerp_nearly_parallel_is_stable():
    q0 = _axis_angle_quat([0, 0, 1], 0.2)
    q1 = _axis_angle_quat([0, 0, 1], 0.2 + 1e-9)
    q = slerp(q0, q1, np.array([0.0, 0.5, 1.0]))
    assert np.all(np.isfinite(q))
    np.testing.assert_allclose(q[1], _axis_angle_quat([0, 0, 1], 0.2 + 0.5e-9), atol=1e-12)


def _quat_mul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def _path_pair(rng):
    m0, _, _ = _random_trs(rng)
    m1, _, _ = _random_trs(rng)
    return m0, m1


def test_path_matrices_and_points_at_ends():
    rng = np.random.default_rng(2)
    m0, m1 = _path_pair(rng)
    path = TransformPath(m0, m1)
    assert not path.static
    np.testing.assert_allclose(path.matrices(0.0), m0, atol=1e-12)
    np.testing.assert_allclose(path.matrices(1.0), m1, atol=1e-12)
    local = rng.normal(size=(10, 3))
    np.testing.assert_allclose(path.points(local, 0.0), local @ m0[:3, :3].T + m0[:3, 3],
                               atol=1e-12)
    np.testing.assert_allclose(path.points(local, 1.0), local @ m1[:3, :3].T + m1[:3, 3],
                               atol=1e-12)
    s = rng.random(10)
    m = path.matrices(s)
    assert m.shape == (10, 4, 4)
    np.testing.assert_allclose(path.points(local, s),
                               np.einsum("nij,nj->ni", m[:, :3, :3], local) + m[:, :3, 3])


def test_path_interpolates_scale_without_shrinking_rotation():
    # Component-wise lerp of two rotation matrices shrinks the middle; the TRS path keeps the
    # determinant at the lerped scale product.
    m0 = compose([0, 0, 0], _axis_angle_quat([0, 0, 1], 0.0), [1, 1, 1])
    m1 = compose([2, 0, 0], _axis_angle_quat([0, 0, 1], math.pi * 0.9), [3, 1, 1])
    mid = TransformPath(m0, m1).matrices(0.5)
    np.testing.assert_allclose(np.linalg.det(mid[:3, :3]), 2.0, rtol=1e-12)
    np.testing.assert_allclose(mid[:3, 3], [1, 0, 0])
    t, q, s = decompose(mid)
    np.testing.assert_allclose(s, [2, 1, 1], rtol=1e-12)
    assert _quat_angle(q, _axis_angle_quat([0, 0, 1], 0.0)) == pytest.approx(math.pi * 0.45)


def test_static_path():
    m = compose([1, 2, 3], _axis_angle_quat([1, 0, 0], 0.3), [2, 2, 2])
    path = TransformPath(m, m.copy())
    assert path.static
    local = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]])
    np.testing.assert_array_equal(path.point_velocities(local, 0.5, 0.1), 0.0)
    np.testing.assert_allclose(path.points(local, 0.3), local @ m[:3, :3].T + m[:3, 3])
    assert path.matrices(np.zeros(4)).shape == (4, 4, 4)


def test_point_velocities_of_rotation_are_omega_cross_r():
    # A rotation of `angle` about axis a through centre c over `duration`: v = w x (x - c) with
    # w = angle / duration * a. Central difference of width 2e-4 in s: relative error
    # ~ (w duration ds)^2 / 6 < 1e-8.
    rng = np.random.default_rng(4)
    axis = np.array([1.0, -1.0, 2.0]) / math.sqrt(6.0)
    angle, duration = 1.2, 0.5
    centre = np.array([0.5, 0.0, -1.0])
    scale = np.array([1.5, 0.5, 2.0])
    q1 = _axis_angle_quat(axis, angle)

    # x = R(s) S l + centre: the transform turns about `centre`
    m0 = compose(centre, [1.0, 0.0, 0.0, 0.0], scale)
    m1 = compose(centre, q1, scale)
    path = TransformPath(m0, m1)
    local = rng.normal(size=(20, 3))
    s = rng.uniform(0.05, 0.95, size=20)
    x = path.points(local, s)
    w = angle / duration * axis
    v = path.point_velocities(local, s, duration)
    np.testing.assert_allclose(v, np.cross(w, x - centre), rtol=1e-6, atol=1e-8)
    # at s = 1 the difference is one-sided over [1 - ds, 1]: the chord is the tangent at
    # 1 - ds/2, off by angle * ds / 2 in direction, so |error| <= |v| * angle * ds
    x1 = path.points(local, 1.0)
    exact = np.cross(w, x1 - centre)
    v_end = path.point_velocities(local, np.ones(20), duration)
    bound = np.linalg.norm(exact, axis=1).max() * angle * 1e-4
    assert np.abs(v_end - exact).max() <= bound


def test_point_velocities_add_local_velocity():
    # A deforming mesh: the local velocity is mapped by the linear part at s.
    m0 = compose([0, 0, 0], _axis_angle_quat([0, 0, 1], 0.0), [2, 2, 2])
    m1 = compose([1, 0, 0], _axis_angle_quat([0, 0, 1], 0.0), [2, 2, 2])
    path = TransformPath(m0, m1)
    local = np.zeros((1, 3))
    v = path.point_velocities(local, 0.5, 0.25, local_velocity=np.array([[0.0, 1.0, 0.0]]))
    np.testing.assert_allclose(v, [[4.0, 2.0, 0.0]], atol=1e-9)


def test_sub_frame_keys_follow_an_arc_that_two_ends_cannot():
    """An object orbiting 90 degrees in one frame: with 8 sub-frame keys its interpolated
    position stays within the chord sagitta of 11.25-degree segments of the circle, while the
    two-key path cuts straight across (error up to R(1 - cos 45deg))."""
    from physanim.core.transforms import TransformPath

    radius = 2.0

    def orbit(angle):
        m = np.eye(4)
        m[:3, 3] = (radius * np.cos(angle), radius * np.sin(angle), 0.0)
        return m

    keys = np.stack([orbit(a) for a in np.linspace(0.0, np.pi / 2, 9)])
    fine = TransformPath(keys[0], keys[-1], keys)
    coarse = TransformPath(keys[0], keys[-1])
    s = np.linspace(0.0, 1.0, 101)
    r_fine = np.linalg.norm(fine.matrices(s)[:, :3, 3], axis=1)
    r_coarse = np.linalg.norm(coarse.matrices(s)[:, :3, 3], axis=1)
    sagitta = radius * (1.0 - np.cos(np.pi / 2 / 8 / 2))
    assert np.all(np.abs(r_fine - radius) <= sagitta + 1e-12)
    assert np.max(radius - r_coarse) > 0.25 * radius
    assert np.allclose(fine.matrices(np.linspace(0, 1, 9)), keys)


def test_matrix_rotation_vector_inverts_rotation_vector_matrix():
    # Axis times angle back from the matrix, for angles from zero up to just below pi, and
    # about the x axis through pi itself (the angle is taken in [0, pi]).
    from physanim.core.transforms import matrix_rotation_vector, rotation_vector_matrix
    rng = np.random.default_rng(3)
    for angle in (0.0, 1e-9, 0.3, 2.0, 3.1):
        axis = rng.normal(size=3)
        theta = angle * axis / np.linalg.norm(axis)
        np.testing.assert_allclose(matrix_rotation_vector(rotation_vector_matrix(theta)), theta,
                                   atol=1e-12)
    half_turn = matrix_rotation_vector(np.diag([1.0, -1.0, -1.0]))
    np.testing.assert_allclose(np.abs(half_turn), [np.pi, 0.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("shape", [(1, 1), (1, 3), (7, 1), (500, 3), (400, 4), (4096, 3)])
def test_narrow_reductions_equal_numpys(shape):
    # column_min/column_max/row_max/row_any/row_all give numpy's axis reductions value for
    # value (dtype too), NaN and infinities included, for floats and integers
    rng = np.random.default_rng(shape[0])
    a = rng.normal(0.0, 1e3, shape)
    a[rng.random(shape) < 0.01] = np.inf
    a[rng.random(shape) < 0.01] = -np.inf
    whole = (np.nan_to_num(a, posinf=1e6, neginf=-1e6) * 7).astype(np.int64)
    for x in (a, np.where(rng.random(shape) < 0.02, np.nan, a), whole):
        for got, want in ((column_min(x), x.min(axis=0)), (column_max(x), x.max(axis=0)),
                          (row_max(x), x.max(axis=1))):
            assert got.dtype == want.dtype
            np.testing.assert_array_equal(got, want)
    m = rng.random(shape) < 0.3
    for got, want in ((row_any(m), m.any(axis=1)), (row_all(~m), (~m).all(axis=1))):
        assert got.dtype == bool
        np.testing.assert_array_equal(got, want)


def test_cross_equals_numpys_bit_for_bit():
    # the same values as np.cross (bit for bit: the same products and differences), dtype and
    # broadcasting included, into a given output too; 2-vectors are np.cross's own
    rng = np.random.default_rng(3)
    u, v = rng.normal(0.0, 1e3, (500, 3)), rng.normal(0.0, 1e-3, (500, 3))
    w = rng.normal(size=(7, 1, 3))
    cases = [(u, v), (u[0], v), (u, v[0]), (w, u[:5]), (u[0], v[0]), ((0.0, 0.0, 1.0), u),
             (rng.integers(-9, 9, (50, 3)), rng.integers(-9, 9, (50, 3))),
             (rng.integers(-9, 9, (50, 3)), v[:50]), (u[:, :2], v[:, :2])]
    for a, b in cases:
        got, want = cross(a, b), np.cross(a, b)
        assert got.shape == want.shape and got.dtype == want.dtype
        np.testing.assert_array_equal(got, want)
    out = np.empty((500, 3))
    assert cross(u, v, out=out) is out
    np.testing.assert_array_equal(out, np.cross(u, v))
    # as a cross product: orthogonal to both, |u x v| = |u| |v| sin, and anti-symmetric
    c = cross(u, v)
    np.testing.assert_allclose(np.einsum("ij,ij->i", c, u) / (np.linalg.norm(c, axis=1)
                               * np.linalg.norm(u, axis=1)), 0.0, atol=1e-12)
    np.testing.assert_array_equal(cross(v, u), -c)


def test_one_point_is_mapped_as_it_is_among_many():
    """BLAS rounds a single row (gemv) unlike several (gemm): a point alone must be mapped to
    the bits it gets among others (a sub-step computing fewer particles gives the same)."""
    rng = np.random.default_rng(2)
    for _ in range(40):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        m = np.eye(4)
        m[:3, :3] = q * rng.uniform(0.5, 2.0, 3)
        m[:3, 3] = rng.normal(size=3)
        x = rng.normal(size=(50, 3)) * 10.0
        many = transform_points(m, x)
        for i in range(0, 50, 7):
            assert np.array_equal(transform_points(m, x[i:i + 1])[0], many[i])


def test_row_scaling_and_single_matrix_maps_by_columns_equal_the_broadcasts_to_the_bit():
    """scale_rows / divide_rows and transform_vectors / transform_points with one matrix work
    column by column (numpy runs (n, 1) x (n, 3) and (n, 3) x (3,) broadcasts row by row); the
    values must be the broadcasts' exactly, including empty and single-row inputs."""
    from physanim.core.transforms import divide_rows, scale_rows, transform_points, \
        transform_vectors, where_rows

    rng = np.random.default_rng(11)
    for n in (0, 1, 2, 257):
        a = rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-5, 5, size=(n, 1))
        s = rng.normal(size=n)
        assert np.array_equal(scale_rows(a, s), a * s[:, None])
        assert np.array_equal(divide_rows(a, s), a / s[:, None])
        out = a.copy()
        scale_rows(out, s, out=out)
        assert np.array_equal(out, a * s[:, None])
        m = rng.normal(size=(4, 4))
        assert np.array_equal(transform_vectors(m[:3, :3], a),
                              a[:, 0:1] * m[:3, 0] + a[:, 1:2] * m[:3, 1] + a[:, 2:3] * m[:3, 2])
        if n != 1:  # (one row goes through its own branch, unchanged)
            assert np.array_equal(transform_points(m, a), a @ m[:3, :3].T + m[:3, 3])
        cond = rng.random(n) < 0.5
        other = rng.normal(size=(n, 3))
        assert np.array_equal(where_rows(cond, a, other), np.where(cond[:, None], a, other))
        up = np.array([0.0, 0.0, 1.0])
        assert np.array_equal(where_rows(cond, a, up), np.where(cond[:, None], a, up))
    wide = rng.normal(size=(5, 12))
    assert np.array_equal(scale_rows(wide, np.arange(5.0)), wide * np.arange(5.0)[:, None])
