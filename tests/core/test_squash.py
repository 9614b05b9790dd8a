"""Squash and stretch (core/controls/squash.py): volume kept exactly, stretch along the velocity,
squash along the impact normal recovering as exp(-age / recovery), impacts found in the motion
of a bouncing ball exactly where it bounces."""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core.controls import (ImpactTracker, SquashSettings, euler_xyz, log_deformation,
                                    principal)
from physanim.core.controls.squash import SQUASH, STRETCH


def _exp(rotation, scale):
    return rotation @ (scale[:, :, None] * np.swapaxes(rotation, 1, 2))


def test_volume_is_kept_whatever_the_motion():
    rng = np.random.default_rng(3)
    n = 2000
    L = log_deformation(rng.normal(0, 20, (n, 3)), rng.normal(0, 8, (n, 3)),
                        rng.uniform(0, 1, n), SquashSettings(amount=2.0))
    rotation, scale = principal(L)
    np.testing.assert_allclose(np.prod(scale, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(rotation), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(_exp(rotation, scale)), 1.0, atol=1e-10)


def test_stretch_along_the_velocity_in_flight():
    v = np.array([[3.0, 4.0, 0.0]])  # 5 m/s
    rotation, scale = principal(log_deformation(v, np.zeros((1, 3)), np.zeros(1),
                                                SquashSettings(amount=1.5)))
    a = math.exp(1.5 * STRETCH * 5.0)
    S = _exp(rotation, scale)[0]
    d = v[0] / 5.0
    assert d @ S @ d == pytest.approx(a, rel=1e-12)
    across = np.array([0.0, 0.0, 1.0])
    assert across @ S @ across == pytest.approx(a ** -0.5, rel=1e-12)


@pytest.mark.parametrize("age", [0.0, 0.15, 0.45])
def test_squash_along_the_normal_recovers_exponentially(age):
    settings = SquashSettings(amount=1.0, recovery=0.15)
    impact = np.array([[0.0, 0.0, 8.0]])  # the velocity jumped up by 8 m/s
    rotation, scale = principal(log_deformation(np.zeros((1, 3)), impact, np.array([age]),
                                                settings))
    S = _exp(rotation, scale)[0]
    b = math.exp(-SQUASH * 8.0 * math.exp(-age / 0.15))
    assert S[2, 2] == pytest.approx(b, rel=1e-12)
    assert S[0, 0] == pytest.approx(b ** -0.5, rel=1e-12)


def test_euler_angles_give_the_rotation_back():
    rng = np.random.default_rng(5)
    rotation, _ = principal(log_deformation(rng.normal(size=(50, 3)), rng.normal(size=(50, 3)),
                                            np.zeros(50), SquashSettings()))
    x, y, z = euler_xyz(rotation).T
    c, s = np.cos, np.sin
    rx = np.stack([np.ones_like(x), 0 * x, 0 * x, 0 * x, c(x), -s(x), 0 * x, s(x), c(x)], 1)
    ry = np.stack([c(y), 0 * y, s(y), 0 * y, np.ones_like(y), 0 * y, -s(y), 0 * y, c(y)], 1)
    rz = np.stack([c(z), -s(z), 0 * z, s(z), c(z), 0 * z, 0 * z, 0 * z, np.ones_like(z)], 1)
    rebuilt = rz.reshape(-1, 3, 3) @ ry.reshape(-1, 3, 3) @ rx.reshape(-1, 3, 3)
    np.testing.assert_allclose(rebuilt, rotation, atol=1e-12)


def test_a_bouncing_balls_impacts_are_found_where_it_bounces():
    """A ball dropped from 2 m bouncing with restitution 0.7, sampled at 24 fps: the tracker
    finds an impact in each interval holding a bounce, pointing up, and none in free flight."""
    g, e, dt = 9.81, 0.7, 1.0 / 24.0
    times = np.arange(0, 3.0, dt)
    bounces, t, v_up = [], math.sqrt(2 * 2.0 / g), math.sqrt(2 * 9.81 * 2.0) * 0.7
    while t < 3.0:
        bounces.append((t, v_up))
        t += 2 * v_up / g
        v_up *= e
    velocity = np.zeros((len(times), 1, 3))
    for k, time in enumerate(times):
        last = [b for b in bounces if b[0] <= time]
        velocity[k, 0, 2] = (last[-1][1] - g * (time - last[-1][0])) if last else -g * time
    tracker = ImpactTracker(SquashSettings(threshold=0.5), (0.0, 0.0, -g))
    found = []
    for k in range(len(times)):
        impact, age = tracker.update(np.array([7]), velocity[k], dt)
        if age[0] == 0.0:
            found.append(k)
            assert impact[0, 2] > 0 and abs(impact[0, 0]) < 1e-12
    expected = [int(math.ceil(b[0] / dt - 1e-9)) for b in bounces
                if b[1] + g * dt > 0.5 / (1 + e) and b[0] < times[-1]]
    assert found[:len(expected)] == expected[:len(found)] and len(found) >= 4
    # between bounces the ages grow by dt, exactly
    impact, age = tracker.update(np.array([7]), velocity[-1] - np.array([[0, 0, 9.81 * dt]]), dt)
    assert age[0] > 0.0


def test_settings_refuse_bad_values():
    with pytest.raises(ValueError, match="recovery must be finite and > 0"):
        SquashSettings(recovery=0.0)
    with pytest.raises(ValueError, match="amount must be finite and >= 0"):
        SquashSettings(amount=-1.0)
