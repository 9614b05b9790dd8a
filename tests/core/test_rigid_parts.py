"""The rigid bodies' small parts: quaternion algebra, contact colouring, soft constraints, the
normal blocks of a manifold and their complementary solutions."""
from __future__ import annotations

import math
import pickle
from types import SimpleNamespace

import numpy as np
import pytest

from physanim.core.rigid import dynamics
from physanim.core.rigid import quaternion as quat
from physanim.core.colouring import colour
from physanim.core.transforms import tangents
from physanim.core.rigid import contact_solver as cs_
from physanim.core.rigid.contact_solver import Softness
from physanim.core.rigid.manifold_blocks import subset_blocks
from physanim.tests.core.rigid_helpers import box, ground, run, world


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
    groups = colour(np.stack([a, b], axis=1), dynamic)
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


def _rows(rng, g):
    """(g, 4, 6) normal rows of four contact points each over the 6 velocities of a body
    (M = 1): some with four coplanar points' rank 3 (a face on a face), some with a point
    repeated (rank-deficient sub-blocks)."""
    j = rng.normal(size=(g, 4, 6))
    j[: g // 3, 3] = j[: g // 3, :3].mean(axis=1)  # four rows spanning three
    j[g // 3: 2 * g // 3, 1] = j[g // 3: 2 * g // 3, 0]  # a point twice
    return j


def _couplings(rng, g):
    """(g, 4, 4) K = J M^-1 J^T of :func:`_rows`."""
    j = _rows(rng, g)
    return np.einsum("gij,gkj->gik", j, j)


def test_subset_blocks_are_the_pseudo_inverses_of_every_principal_sub_block():
    rng = np.random.default_rng(5)
    k = _couplings(rng, 30)
    blocks = subset_blocks(k, np.linalg.pinv(k, rcond=1e-10, hermitian=True))
    assert blocks.shape == (30, 16, 4, 4)
    for c in range(16):
        slots = [i for i in range(4) if c >> i & 1]
        for g in range(30):
            want = np.zeros((4, 4))
            if slots:
                sub = k[g][np.ix_(slots, slots)]
                want[np.ix_(slots, slots)] = np.linalg.pinv(sub, rcond=1e-10, hermitian=True)
            assert np.allclose(blocks[g, c], want, rtol=1e-7, atol=1e-9 * np.abs(want).max())


def _lcp(k, rel, old, valid):
    """The normal impulses of manifolds (hard contacts, no bias) by the solver's subset
    enumeration."""
    g = len(k)
    block = np.linalg.pinv(k, rcond=1e-10, hermitian=True)
    cs = SimpleNamespace(valid=valid, coupling=k, subsets=subset_blocks(k, block))
    sc = SimpleNamespace(mass=np.ones((g, 4)), bias=np.zeros((g, 4)), impulse=np.zeros((g, 4)))
    return cs_._enumerated(cs, sc, np.arange(g), rel, old)


def test_enumerated_normal_impulses_are_complementary():
    """Each point pushes (impulse >= 0) and is then left not approaching, or lets go (impulse
    0) and is left separating: x >= 0, w = rel + K (x - old) >= 0, x w = 0."""
    rng = np.random.default_rng(8)
    g = 300
    j = _rows(rng, g)
    k = np.einsum("gij,gkj->gik", j, j)
    rel = np.einsum("gij,gj->gi", j, rng.normal(size=(g, 6)))  # of some velocity
    old = np.maximum(rng.normal(size=(g, 4)), 0.0)
    valid = np.arange(4) < rng.integers(1, 5, g)[:, None]  # 1 to 4 points
    k = np.where(valid[:, :, None] & valid[:, None, :], k, np.eye(4))
    x, solved = _lcp(k, rel, np.where(valid, old, 0.0), valid)
    assert solved.all()
    w = rel + np.einsum("gij,gj->gi", k, x - old * valid)
    scale = np.abs(rel).max() + np.abs(k).max() * np.abs(x).max()
    assert (x >= 0.0).all() and (x[~valid] == 0.0).all()
    assert (w[valid] > -1e-9 * scale).all()
    assert np.abs(x * w)[valid].max() < 1e-9 * scale ** 2


def test_a_symmetric_load_on_four_coplanar_points_is_shared_equally():
    """A box resting flat: four points of one face, the load pressing the middle and the
    corner rows rank 3 — the four impulses come out equal (a point-by-point pass would
    load whichever came first)."""
    corners = np.array([[1, 1], [1, -1], [-1, 1], [-1, -1]], float) * 0.25
    inv_mass, inv_inertia = 1.0, np.array([3.0, 3.0, 2.0])
    arm = np.column_stack([corners, np.full(4, -0.25)])
    ang = np.cross(arm, [0.0, 0.0, 1.0])
    k = inv_mass + np.einsum("ik,jk->ij", ang * inv_inertia, ang)
    x, solved = _lcp(k[None], np.full((1, 4), -1.0), np.zeros((1, 4)), np.ones((1, 4), bool))
    assert solved.all()
    assert np.allclose(x, x.mean(), rtol=1e-9) and x.min() > 0.0
    assert x.sum() == pytest.approx(1.0 / inv_mass, rel=1e-9)  # stops the fall, exactly


@pytest.mark.parametrize("paths, length, rows", [(1, 100, 6), (3, 37, 5), (2, 65, 6), (2, 1, 4),
                                                  (4, 2, 3), (1, 3, 2), (1, 13, 5), (20, 9, 10),
                                                  (1, 1000, 5)])
def test_block_cyclic_reduction_solves_block_tridiagonal_systems(paths, length, rows):
    # The joints' chain solve against a dense solve of the same symmetric positive definite
    # block-tridiagonal systems (one per path, several right-hand sides), to rounding.
    from physanim.core.rigid.joint_chains import reduce, reduced_solve
    rng = np.random.default_rng(length)
    d = rng.normal(size=(paths, length, rows, rows))
    d = d @ np.swapaxes(d, 2, 3) + 6 * rows * np.eye(rows)
    u = rng.normal(size=(paths, length - 1, rows, rows))
    b = rng.normal(size=(paths, length, rows, 2))
    x = reduced_solve(*reduce(d, u), b)
    for c in range(paths):
        dense = np.zeros((length * rows, length * rows))
        for i in range(length):
            dense[i * rows:(i + 1) * rows, i * rows:(i + 1) * rows] = d[c, i]
            if i < length - 1:
                dense[i * rows:(i + 1) * rows, (i + 1) * rows:(i + 2) * rows] = u[c, i]
                dense[(i + 1) * rows:(i + 2) * rows, i * rows:(i + 1) * rows] = u[c, i].T
        expected = np.linalg.solve(dense, b[c].reshape(-1, 2))
        np.testing.assert_allclose(x[c].reshape(-1, 2), expected, rtol=0,
                                   atol=1e-12 * np.abs(expected).max())


def test_contact_rows_keep_their_fixed_parts_with_the_contacts_but_not_in_a_checkpoint():
    """The rows' directions and linear parts, written once per contact set, give at new poses
    the rows a fresh build gives; a pickled contact set (a resumable bake's state) leaves them
    out."""
    model, solver, state = world(*[box(f"B{k}", (0.25, 0.25, 0.25), (0.1 * k, 0.0, 0.3 + 0.6 * k))
                                   for k in range(3)])
    run(solver, state, 24, colliders=[ground()])
    cs = state.contacts.contacts
    inv_mass = np.concatenate([model.body_inv_mass, [0.0]])  # the bodies, then the ground
    inertia = np.zeros((4, 3, 3))
    inertia[:3] = dynamics.world_tensor(state.body_q, model.body_inv_inertia)
    cs_.rows(cs, inv_mass, inertia, cs.ra, cs.rb)
    assert cs.rows_buffer is not None
    turn = quat.to_matrix(quat.normalized(np.array([[1.0, 0.1, -0.2, 0.05]])))[0]
    ra, rb = cs.ra @ turn.T, cs.rb @ turn.T  # the bodies turned: new arms and inertias
    inertia[:3] = dynamics.world_tensor(quat.multiply(np.array([0.9, 0.1, 0.3, 0.0]) /
                                                      np.linalg.norm([0.9, 0.1, 0.3, 0.0]),
                                                      state.body_q), model.body_inv_inertia)
    kept = cs_.rows(cs, inv_mass, inertia, ra, rb)
    fresh = pickle.loads(pickle.dumps(cs))
    assert fresh.rows_buffer is None
    built = cs_.rows(fresh, inv_mass, inertia, ra, rb)
    for f in ("jn", "mn", "mass_n", "jt", "mt", "mass_t"):
        assert np.array_equal(getattr(kept, f), getattr(built, f)), f
