"""Free rigid-body motion against closed forms: projectile, torque-free angular momentum, the
intermediate-axis (Dzhanibekov) flip."""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.rigid import quaternion as quat
from physanim.core.rigid.mass import MassProperties
from physanim.core.rigid.model import RigidBodySettings
from physanim.tests.core.rigid_helpers import DT, G, box, run, world


def test_projectile_matches_the_semi_implicit_closed_form():
    """v_{k+1} = v_k + g h, x_{k+1} = x_k + h v_{k+1}: after n steps of h, t = n h,
    x = x0 + v0 t + g t^2 / 2 + g t h / 2 exactly (the method's first-order term)."""
    v0 = np.array([3.0, -1.0, 7.0])
    model, solver, state = world(box("B", (0.1, 0.2, 0.3), (0.0, 0.0, 5.0), velocity=tuple(v0),
                                     linear_damping=0.0, angular_damping=0.0), substeps=4)
    frames = 48
    run(solver, state, frames)
    t, h = frames * DT, DT / 4
    expected = np.array([0.0, 0.0, 5.0]) + v0 * t + 0.5 * np.array(G) * t * (t + h)
    np.testing.assert_allclose(state.origins(model)[0], expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(state.body_P[0], v0 + np.array(G) * t, rtol=0, atol=1e-9)


def _spinning(inertia, w0, substeps=8):
    props = MassProperties(1.0, (0.0, 0.0, 0.0), np.diag(inertia), 1.0)
    body = RigidBodySettings("T", "BOX", props, half_extents=(0.1, 0.1, 0.1),
                             angular_velocity=tuple(w0), linear_damping=0.0,
                             angular_damping=0.0)
    return world(body, substeps=substeps)


def test_torque_free_motion_keeps_angular_momentum_exactly():
    model, solver, state = _spinning((1.0, 2.0, 2.5), (0.3, 4.0, -1.2))
    L0 = state.body_L[0].copy()
    worst = []
    run(solver, state, int(10.0 / DT), gravity=(0.0, 0.0, 0.0),
        each=lambda f, s: worst.append(np.linalg.norm(s.body_L[0] - L0)))
    assert max(worst) <= 1e-9 * np.linalg.norm(L0)


def _axis_along_L(inertia, axis, frames=int(20.0 / 0.04)):
    """Dot of the body's ``axis`` with L, per frame, spinning mostly about it."""
    w0 = np.full(3, 0.01)
    w0[axis] = 6.0
    model, solver, state = _spinning(inertia, w0)
    L = state.body_L[0] / np.linalg.norm(state.body_L[0])
    local = np.zeros(3)
    local[axis] = 1.0
    out = []
    run(solver, state, frames, gravity=(0.0, 0.0, 0.0),
        each=lambda f, s: out.append(float(quat.rotate(s.body_q[0], local) @ L)))
    return np.array(out)


def test_intermediate_axis_flips_periodically():
    """A T-handle spun about its intermediate axis turns over again and again (Dzhanibekov)."""
    dots = _axis_along_L((1.0, 2.0, 3.0), 1)
    flips = np.count_nonzero(np.diff(np.sign(dots)) != 0)
    assert dots.min() < -0.9 and dots.max() > 0.9
    assert flips >= 4  # periodic: it comes back, and turns over again


@pytest.mark.parametrize("axis", [0, 2])
def test_largest_and_smallest_axes_are_stable(axis):
    dots = _axis_along_L((1.0, 2.0, 3.0), axis)
    assert dots.min() > 0.99


def test_kinetic_energy_of_free_rotation_stays_bounded():
    """The Lie midpoint rule does not pump energy into a free rotation."""
    model, solver, state = _spinning((1.0, 2.0, 3.0), (0.01, 6.0, 0.01))
    inv = model.body_inv_inertia[0]

    def energy(s):
        r = quat.to_matrix(s.body_q[:1])[0]
        L = s.body_L[0]
        return 0.5 * L @ (r @ inv @ r.T) @ L

    e0 = energy(state)
    energies = []
    run(solver, state, 500, gravity=(0.0, 0.0, 0.0), each=lambda f, s: energies.append(energy(s)))
    assert max(abs(e - e0) for e in energies) < 0.02 * e0
