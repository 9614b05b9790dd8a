"""Follow-through (core/controls/follow.py) against the damped oscillator's closed forms: a
follower at rest on a target that sets off at speed u lags it as -(u / w_d) e^(-z w t)
sin(w_d t), and when the target stops it runs on and swings back; exact at any sampling."""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core.controls import FollowSettings, follow_through


def _set_off(speed: float, times: np.ndarray) -> np.ndarray:
    """A target at rest until t = 0, then moving along x at ``speed``."""
    target = np.zeros((len(times), 3))
    target[:, 0] = speed * np.maximum(times, 0.0)
    return target


@pytest.mark.parametrize("damping", [0.0, 0.3, 1.0, 2.5])
def test_a_target_setting_off_leaves_the_follower_behind_as_the_closed_form_says(damping):
    settings = FollowSettings(frequency=1.5, damping=damping)
    w = 2.0 * math.pi * settings.frequency
    u = 3.0
    times = np.concatenate([[-1.0], np.linspace(0.0, 4.0, 97)])
    c = follow_through(times, _set_off(u, times), settings)
    t = times[1:]
    if damping < 1.0:
        wd = w * math.sqrt(1.0 - damping ** 2)
        lag = -u / wd * np.exp(-damping * w * t) * np.sin(wd * t)
    elif damping == 1.0:
        lag = -u * t * np.exp(-w * t)
    else:
        r = w * math.sqrt(damping ** 2 - 1.0)
        lag = -u / r * np.exp(-damping * w * t) * np.sinh(r * t)
    np.testing.assert_allclose(c[1:, 0] - u * t, lag, atol=1e-12 * u / w)
    np.testing.assert_allclose(c[:, 1:], 0.0, atol=1e-15)


def test_when_the_target_stops_the_follower_runs_on_then_settles():
    settings = FollowSettings(frequency=2.0, damping=0.2)
    w = 2.0 * math.pi * settings.frequency
    wd = w * math.sqrt(1.0 - 0.2 ** 2)
    u, stop = 2.0, 3.0
    times = np.linspace(0.0, 6.0, 601)
    target = np.zeros((len(times), 3))
    target[:, 0] = u * np.minimum(times, stop)  # moving from the start (no lag), then stops
    c = follow_through(times, target, settings)
    after = times >= stop
    tau = times[after] - stop
    overshoot = u / wd * np.exp(-0.2 * w * tau) * np.sin(wd * tau)
    np.testing.assert_allclose(c[after, 0] - u * stop, overshoot, atol=1e-11)
    assert (c[~after, 0] == target[~after, 0]).all()  # steady motion: no lag at all
    assert c[:, 0].max() > u * stop + 0.5 * u / wd  # it ran on past the stop


def test_exact_whatever_the_sampling():
    """The target is piecewise linear between samples: 4 or 400 samples over the same straight
    runs give the same follower at the shared times (to rounding)."""
    settings = FollowSettings(frequency=3.0, damping=0.1)
    coarse = np.array([0.0, 1.0, 1.5, 3.0])
    path = np.array([[0, 0, 0], [1, 2, 0], [1, 2, 3], [0, 0, 0]], float)
    fine = np.linspace(0.0, 3.0, 601)
    fine_path = np.stack([np.interp(fine, coarse, path[:, k]) for k in range(3)], axis=1)
    a = follow_through(coarse, path, settings)
    b = follow_through(fine, fine_path, settings)
    np.testing.assert_allclose(b[np.searchsorted(fine, coarse)], a, atol=1e-10)


def test_undamped_swing_keeps_its_amplitude_and_many_followers_at_once():
    settings = FollowSettings(frequency=1.0, damping=0.0)
    w = 2.0 * math.pi
    times = np.concatenate([[-1.0], np.linspace(0.0, 200.0, 20001)])
    targets = np.stack([_set_off(1.0, times), _set_off(-2.0, times)], axis=1)  # (F, 2, 3)
    c = follow_through(times, targets, settings)
    swing = c[:, :, 0] - targets[:, :, 0]
    late = times > 190.0
    np.testing.assert_allclose(np.abs(swing[late]).max(axis=0), [1.0 / w, 2.0 / w], rtol=1e-6)


def test_bad_settings_and_samples_say_what_is_wrong():
    with pytest.raises(ValueError, match="frequency must be finite and > 0 Hz"):
        FollowSettings(frequency=0.0)
    with pytest.raises(ValueError, match="damping ratio must be finite and >= 0"):
        FollowSettings(damping=-1.0)
    with pytest.raises(ValueError, match="times must increase"):
        follow_through(np.array([0.0, 0.0]), np.zeros((2, 3)), FollowSettings())
    with pytest.raises(ValueError, match=r"\(F, \.\.\., 3\) targets"):
        follow_through(np.array([0.0, 1.0]), np.zeros((2, 2)), FollowSettings())
