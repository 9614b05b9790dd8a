"""Internal spring-mesh forces: momentum conservation, dihedral gradients, bending restores.

Internal forces (pair springs, angular springs) must add no net force and no net torque: the
pair force acts along x_i - x_j, equal and opposite; the angular force is -torque * d(theta)/dx
and theta is invariant under translation and rotation, so its gradient sums to zero force and
zero torque. Both hold to rounding: relative 1e-9 of the summed force magnitudes is ~1e6 ulps.
"""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.forces import ParticleView
from physanim.core.springs import SpringMeshBuilder, SpringMeshSettings, topology
from physanim.core.forces import DampedSprings
from physanim.core.springs.forces import (FADE_AREA, AngularSprings, dihedral_gradients,
                                         hinge_normals)
from physanim.tests.core.helpers import grid as _grid


def _model(nx: int = 7, ny: int = 6):
    x, edges, tris, ls, lt, lv = _grid(nx, ny)
    settings = SpringMeshSettings("Cloth", stiffness=800.0, damping=3.0, shear_stiffness=300.0,
                                  shear_damping=1.5, bend_mode="ANGULAR", bend_stiffness=0.7,
                                  bend_damping=0.2)
    return SpringMeshBuilder(settings, x, edges, tris, ls, lt, lv).finalize()


def _deformed(model, seed: int):
    """A randomly crumpled, moved and rotated copy of the rest mesh with random velocities."""
    rng = np.random.default_rng(seed)
    x = model.rest_x + rng.normal(scale=0.08, size=model.rest_x.shape)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    x = x @ q.T + rng.normal(scale=5.0, size=3)  # far from the origin: torque arms matter
    v = rng.normal(scale=2.0, size=x.shape)
    return ParticleView(x, v, model.vertex_mass, 0.0)


def _forces(model):
    return [DampedSprings(model.spring_i, model.spring_j, model.spring_rest, model.spring_stiffness,
                      model.spring_damping),
            AngularSprings(model.hinge, model.hinge_rest, model.settings.bend_stiffness,
                           model.settings.bend_damping)]


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("which", ["springs", "angular"])
def test_internal_forces_conserve_linear_and_angular_momentum(seed, which):
    model = _model()
    assert len(model.hinge) and np.any(model.spring_family == 1)  # shear springs are in
    view = _deformed(model, seed)
    force = _forces(model)[0 if which == "springs" else 1]
    f = np.zeros_like(view.x)
    force.apply(view, f)
    magnitude = np.abs(f).sum()
    assert magnitude > 1.0  # a real deformation, not a trivial zero
    np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-9 * magnitude)
    torque = np.cross(view.x, f).sum(axis=0)
    lever = (np.linalg.norm(view.x, axis=1) * np.linalg.norm(f, axis=1)).sum()
    np.testing.assert_allclose(torque, 0.0, atol=1e-9 * lever)


def _random_hinges(seed: int, count: int = 40):
    """Non-degenerate hinges bent well away from +-pi (where the angle wraps)."""
    rng = np.random.default_rng(seed)
    x = []
    for _ in range(count):
        e0, e1 = rng.normal(size=3), rng.normal(size=3)
        mid, axis = 0.5 * (e0 + e1), e1 - e0
        side = np.cross(axis, rng.normal(size=3))
        side /= np.linalg.norm(side)
        up = np.cross(axis / np.linalg.norm(axis), side)
        bend = rng.uniform(-2.5, 2.5)  # dihedral angle
        w0 = mid + side + 0.1 * rng.normal(size=3)
        w1 = mid - np.cos(bend) * side + np.sin(bend) * up
        x += [e0, e1, w0, w1]
    x = np.array(x)
    return x, np.arange(len(x)).reshape(-1, 4)


@pytest.mark.parametrize("seed", [4, 5])
def test_dihedral_gradients_match_central_differences(seed):
    """Central differences err by O(eps^2 theta''') ~ 1e-12 plus rounding 1e-16 / eps ~ 1e-10."""
    x, hinge = _random_hinges(seed)
    theta = topology.dihedral_angles(x, hinge)
    assert np.all(np.abs(theta) < 3.0) and np.ptp(theta) > 2.0
    grad = dihedral_gradients(topology.hinge_geometry(x, hinge))
    eps = 1e-6
    numeric = np.zeros_like(grad)
    for k in range(4):
        for c in range(3):
            xp, xm = x.copy(), x.copy()
            xp[hinge[:, k], c] += eps
            xm[hinge[:, k], c] -= eps
            numeric[:, k, c] = (topology.dihedral_angles(xp, hinge)
                                - topology.dihedral_angles(xm, hinge)) / (2 * eps)
    np.testing.assert_allclose(grad, numeric, atol=1e-7 * np.abs(numeric).max())


def test_flat_hinge_has_zero_angle_and_sign_follows_the_fold():
    x = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0]], float)
    hinge = np.array([[0, 1, 2, 3]])
    assert topology.dihedral_angles(x, hinge)[0] == pytest.approx(0.0, abs=1e-15)
    up, down = x.copy(), x.copy()
    up[3, 2], down[3, 2] = 0.5, -0.5
    a_up, a_down = topology.dihedral_angles(up, hinge)[0], topology.dihedral_angles(down, hinge)[0]
    assert a_up == pytest.approx(-a_down) and abs(a_up) == pytest.approx(np.arctan2(0.5, 1.0))


def _squashed_hinge_forces(height: float, fade: bool, speed: float = 0.0):
    """Forces and Jacobian blocks of one angular spring (rest flat) whose first triangle is
    squashed to ``height`` (its rest height 1) and folded 1 rad about the hinge, its wing
    vertex moving up at ``speed``."""
    rest_x = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0]], float)
    hinge = np.array([[0, 1, 2, 3]])
    springs = AngularSprings(hinge, np.zeros(1), 2.0, 0.5,
                             hinge_normals(rest_x, hinge) if fade else None)
    x = rest_x.copy()
    x[2] = [0.5, height * np.cos(1.0), height * np.sin(1.0)]
    v = np.zeros_like(x)
    v[2, 2] = speed
    view = ParticleView(x, v, np.ones(4), 0.0)
    f = np.zeros_like(x)
    springs.apply(view, f)
    return f, springs.linearize(view).grad, springs


def test_a_hinge_squashed_flat_pushes_with_bounded_forces():
    """A triangle squashed to a line has no normal, so its hinge no angle: the angle's gradient
    grows as one over its area. Below FADE_AREA of its rest area the hinge fades out (forces as
    the area, damping and the Jacobian bounded), while a hinge above it is untouched to the
    bit. Without the fading, the same spring's force grows a thousand-fold per thousand-fold
    squash."""
    heights = [1e-3, 1e-6, 1e-9]
    bare = [np.abs(_squashed_hinge_forces(h, False)[0]).max() for h in heights]
    assert bare[1] > 500.0 * bare[0] and bare[2] > 500.0 * bare[1]
    faded = [_squashed_hinge_forces(h, True) for h in heights]
    for (f, grad, _), h in zip(faded, heights):
        assert np.all(np.isfinite(f)) and np.abs(f).max() < 1e4 * h
        assert np.abs(grad).max() < 20.0
        np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-12)
        assert np.abs(_squashed_hinge_forces(h, True, speed=1.0)[0]).max() < 100.0
    # above the fade: the same forces and Jacobian as a spring that never fades
    h = 2.0 * FADE_AREA
    (f, grad, springs), (f0, grad0, _) = (_squashed_hinge_forces(h, True, 1.0),
                                          _squashed_hinge_forces(h, False, 1.0))
    assert np.array_equal(f, f0) and np.array_equal(grad, grad0)
    # the energy fades with it: a squashed hinge stores nearly none, whatever its angle
    x = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1e-6 * np.cos(1.0), 1e-6 * np.sin(1.0)],
                  [0.5, -1, 0]], float)
    assert springs.energy(x) < 1e-9


@pytest.mark.parametrize("rest", [0.0, 0.6, -1.2])
def test_angular_spring_pushes_a_bent_hinge_back_to_its_rest_angle(rest):
    """Energy E = k/2 (theta - theta0)^2 must decrease along the force (f = -dE/dx), and a small
    step along it brings theta closer to theta0. Damping off, so f is purely elastic."""
    x = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0]], float)
    hinge = np.array([[0, 1, 2, 3]])
    bend = rest + 0.5  # fold the hinge 0.5 rad past its rest angle
    x[3] = [0.5, -np.cos(bend), np.sin(bend)]
    theta = topology.dihedral_angles(x, hinge)[0]
    k = 2.0
    springs = AngularSprings(hinge, np.array([rest]), k, 0.0)
    f = np.zeros_like(x)
    springs.apply(ParticleView(x, np.zeros_like(x), np.ones(4), 0.0), f)
    energy = lambda y: 0.5 * k * (topology.dihedral_angles(y, hinge)[0] - rest) ** 2  # noqa: E731
    # the force is minus the energy gradient: dE along f is -|f|^2 (first order in the step)
    step = 1e-4
    assert energy(x + step * f) < energy(x)
    assert (energy(x + step * f) - energy(x)) / step == pytest.approx(-np.sum(f * f), rel=1e-3)
    after = topology.dihedral_angles(x + step * f, hinge)[0]
    assert abs(after - rest) < abs(theta - rest)
    np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-12)


def test_angular_damping_opposes_the_folding_rate():
    """The damping part -kd theta_dot grad(theta) takes power from the hinge: f . v < 0."""
    x = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0]], float)
    hinge = np.array([[0, 1, 2, 3]])
    v = np.zeros_like(x)
    v[3, 2] = 1.0  # folding the wing up
    springs = AngularSprings(hinge, np.zeros(1), 0.0, 0.5)
    f = np.zeros_like(x)
    springs.apply(ParticleView(x, v, np.ones(4), 0.0), f)
    assert np.sum(f * v) < 0.0


@pytest.mark.parametrize("seed", [4, 5])
def test_spring_jacobian_matches_central_differences_and_products_agree(seed):
    """df/dx and df/dv of the pair springs against central differences of the forces (every
    spring stretched, where the transverse term is exact: it is clamped only for compressed
    springs; df/dx at rest velocities, since like Baraff & Witkin it leaves out how turning a
    damper changes its force), and the matrix-free product against the blocks. Differences of
    O(eps^2): the forces are smooth, eps = 1e-6 m, so 1e-6 relative is ample."""
    model = _model(4, 4)
    rng = np.random.default_rng(seed)
    x = model.rest_x * 1.3 + rng.normal(scale=0.01, size=model.rest_x.shape)  # all stretched
    v = rng.normal(size=x.shape)
    springs = _forces(model)[0]
    jac = springs.linearize(ParticleView(x, v, model.vertex_mass, 0.0))
    n = len(x)

    def force(xx, vv):
        out = np.zeros_like(xx)
        springs.apply(ParticleView(xx, vv, model.vertex_mass, 0.0), out)
        return out.ravel()

    dense = {}
    for name, blocks in (("x", jac.kx), ("v", jac.kv)):
        m = np.zeros((3 * n, 3 * n))
        for (i, j), b in zip(jac.pairs, blocks):
            for r, c, sign in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
                m[3 * r:3 * r + 3, 3 * c:3 * c + 3] += sign * b
        dense[name] = m
    eps = 1e-6
    for name in ("x", "v"):
        numeric = np.zeros((3 * n, 3 * n))
        for k in range(3 * n):
            step = np.zeros(3 * n)
            step[k] = eps
            step = step.reshape(n, 3)
            rest = np.zeros_like(v)
            plus = force(x + step, rest) if name == "x" else force(x, v + step)
            minus = force(x - step, rest) if name == "x" else force(x, v - step)
            numeric[:, k] = (plus - minus) / (2 * eps)
        scale = np.abs(numeric).max()
        assert np.abs(dense[name] - numeric).max() < 1e-6 * scale, name
    w = rng.normal(size=x.shape)
    out = np.zeros_like(w)
    jac.product(0.3, -0.7, w, out)
    expected = (0.3 * dense["x"] - 0.7 * dense["v"]) @ w.ravel()
    np.testing.assert_allclose(out.ravel(), expected, atol=1e-10 * np.abs(expected).max())


def test_angular_springs_reuse_their_geometry_only_at_the_same_positions():
    """The angular springs remember the hinge geometry of the last positions (an implicit step
    asks for forces, energy and Jacobian at its start): the same values as a fresh object at
    every call, whatever the order, after x changed in place, and nothing of it pickled."""
    import pickle

    model = _model()
    springs = AngularSprings(model.hinge, model.hinge_rest, 0.7, 0.2)

    def fresh():
        return AngularSprings(model.hinge, model.hinge_rest, 0.7, 0.2)

    for seed in range(3):
        p = _deformed(model, seed)
        for _ in range(2):  # the second round hits the remembered geometry
            f, f_fresh = np.zeros_like(p.x), np.zeros_like(p.x)
            springs.apply(p, f)
            fresh().apply(p, f_fresh)
            np.testing.assert_array_equal(f, f_fresh)
            assert springs.energy(p.x) == fresh().energy(p.x)
            np.testing.assert_array_equal(springs.linearize(p).grad, fresh().linearize(p).grad)
        p.x[3] += 0.01  # moved in place: no stale geometry
        assert springs.energy(p.x) == fresh().energy(p.x)
        np.testing.assert_array_equal(springs.linearize(p).grad, fresh().linearize(p).grad)
    assert springs._last.x is not None
    assert pickle.loads(pickle.dumps(springs))._last.x is None
