"""Hang time and bounce exaggeration (core/controls/hang.py) on a body's flights: take-off and
landing keep their frames and poses, the path in space is the simulated one, the apex is slow
by (1 - hang time), the height above the take-off-to-landing line is scaled."""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core.controls.hang import FlightSettings, eased, flights, shape_flights

G = np.array([0.0, 0.0, -9.81])
FPS = 24.0


def _bounces(frames: int = 120, e: float = 0.8, vx: float = 1.5, z0: float = 3.0):
    """A ball's centre bouncing on z = 0 with restitution e, sampled at FPS (exact)."""
    t = np.arange(frames) / FPS
    z, vz, tt, out = z0, 0.0, 0.0, []
    hits = []
    for ti in t:
        while True:  # advance from tt to ti, bouncing on the way
            disc = vz * vz + 2 * 9.81 * z
            t_hit = (vz + math.sqrt(disc)) / 9.81  # time from tt to the next contact
            if tt + t_hit <= ti:
                tt += t_hit
                vz = e * math.sqrt(disc)
                z = 0.0
                hits.append(tt)
            else:
                dt = ti - tt
                out.append(z + vz * dt - 4.905 * dt * dt)
                break
    pos = np.stack([vx * t, np.zeros_like(t), np.array(out)], axis=1)
    rot = np.tile([1.0, 0.0, 0.0, 0.0], (frames, 1))
    return t, pos, rot, np.array(hits)


def test_each_bounce_is_one_flight_between_its_contacts():
    t, pos, _, hits = _bounces()
    found = flights(t, pos, G)
    assert len(found) >= 3
    for first, last in found:  # inside one bounce: no contact between its samples
        assert not ((hits > t[first]) & (hits < t[last])).any()
        assert ((hits > t[first] - 2 / FPS) & (hits < t[first])).any()  # just after one
    rest = np.zeros((50, 3))
    assert flights(t[:50], rest, G) == []  # resting is no flight
    rolling = np.stack([t[:50], 0 * t[:50], 0 * t[:50]], axis=1)
    assert flights(t[:50], rolling, G) == []


def test_hang_time_keeps_contacts_and_path_and_slows_the_apex():
    t, pos, rot, _ = _bounces()
    h = 0.6
    shown, q = shape_flights(t, pos, rot, G, FlightSettings(hang_time=h))
    found = flights(t, pos, G)
    assert found
    for first, last in found:
        assert np.array_equal(shown[[first, last]], pos[[first, last]])
        seg = slice(first, last + 1)
        # on the simulated parabola: x tells the time, z must be the parabola's there
        x, z = pos[seg, 0], pos[seg, 2]
        coeff = np.polyfit(x, z, 2)
        assert np.polyval(coeff, shown[seg, 0]) == pytest.approx(shown[seg, 2], abs=1e-9)
        # slow at the apex, fast at the ends: horizontal speed (constant when simulated)
        speed = np.diff(shown[seg, 0]) * FPS / 1.5
        apex = int(np.argmax(shown[seg, 2]))
        assert speed[max(apex - 1, 0):apex + 1].min() == pytest.approx(1 - h, abs=0.12)
        assert speed[0] > 1.0 and speed[-1] > 1.0
    outside = np.ones(len(t), bool)
    for first, last in found:
        outside[first:last + 1] = False
    assert np.array_equal(shown[outside], pos[outside])
    assert np.array_equal(q, rot)  # no spin: orientations unchanged


def test_exaggeration_scales_the_height_above_the_line():
    t, pos, rot, _ = _bounces()
    shown, _ = shape_flights(t, pos, rot, G, FlightSettings(exaggeration=2.5))
    for first, last in flights(t, pos, G):
        seg = slice(first, last + 1)
        line = np.interp(t[seg], t[[first, last]], pos[[first, last], 2])
        assert shown[seg, 2] - line == pytest.approx(2.5 * (pos[seg, 2] - line), abs=1e-12)
        assert np.array_equal(shown[seg, :2], pos[seg, :2])


def test_eased_clock_is_monotone_and_keeps_the_ends():
    u = np.linspace(0.0, 1.0, 1001)
    for apex in (0.2, 0.5, 0.8):
        s = eased(u, apex, 0.9)
        assert s[0] == 0.0 and s[-1] == pytest.approx(1.0, abs=1e-15)
        assert (np.diff(s) > 0.0).all()
        assert eased(np.array([apex]), apex, 0.9)[0] == pytest.approx(apex)
        slope = np.gradient(s, u)
        assert slope[0] == pytest.approx(1.9, abs=1e-2)
        assert slope[int(apex * 1000)] == pytest.approx(0.1, abs=1e-2)


@pytest.mark.parametrize("kwargs", [dict(hang_time=1.0), dict(hang_time=-0.1),
                                    dict(exaggeration=0.0), dict(exaggeration=float("nan"))])
def test_bad_settings_are_refused(kwargs):
    with pytest.raises(ValueError):
        FlightSettings(**kwargs)


def test_a_flight_holding_a_kept_sample_stays_as_simulated():
    """The flight to a body's mark keeps its simulated frames (it must be on the mark then);
    the other flights are shaped."""
    t, pos, rot, _ = _bounces()
    found = flights(t, pos, G)
    first, last = found[0]
    mid = (first + last) // 2
    shown, _ = shape_flights(t, pos, rot, G, FlightSettings(hang_time=0.5, exaggeration=2.0),
                             keep=(mid,))
    assert np.array_equal(shown[first:last + 1], pos[first:last + 1])
    a, b = found[1]
    assert not np.array_equal(shown[a:b + 1], pos[a:b + 1])
