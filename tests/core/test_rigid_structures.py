"""Structures that must stand: a pyramid 20 boxes wide and a house of cards (issue 10's
criteria), at the rigid-body defaults but for the cards' friction."""
from __future__ import annotations

import math

import numpy as np

from physanim.tests.core.rigid_helpers import DT, box, ground, run, world


def test_a_pyramid_twenty_boxes_wide_stands():
    """210 boxes of 0.5 m, rows of 20, 19, ... 1 touching side by side: after the first second
    (the soft contacts take their load) the top box moves less than a millimetre over the
    remaining 9 s, no box is pushed aside more than 1 cm (the base spreads a few millimetres
    as the soft contacts load), and the whole pyramid falls asleep."""
    h, wide = 0.25, 20
    boxes = [box(f"P{row}_{i}", (h, h, h), ((i - (wide - row - 1) / 2) * 2 * h, 0.0,
                                              h + 2 * h * row))
             for row in range(wide) for i in range(wide - row)]
    model, solver, state = world(*boxes)
    start = state.body_x.copy()
    tops = []
    run(solver, state, int(10.0 / DT), colliders=[ground()],
        each=lambda f, s: tops.append(s.body_x[-1].copy()))
    tops = np.array(tops)
    second = int(1.0 / DT)
    assert np.linalg.norm(tops[second:] - tops[second], axis=1).max() < 1e-3
    sideways = np.linalg.norm((state.body_x - start)[:, :2], axis=1)
    assert sideways.max() < 0.01, sideways.max()
    assert state.body_asleep.all()


def _card(name, apex_x, floor_z, lean, side, size, friction):
    """A card leaning ``lean`` [rad] towards the apex at ``apex_x`` (``side`` -1: from the
    left, +1: from the right), its lowest edge on ``floor_z``, its top edge 0.1 mm from the
    apex."""
    length, width, thick = size
    c, s = math.cos(lean), math.sin(lean)
    x = apex_x + side * (thick / 2 * c + length / 2 * s + 1e-4)
    z = floor_z + thick / 2 * s + length / 2 * c
    turn = -side * lean  # about y: the top towards the apex
    return box(name, (thick / 2, width / 2, length / 2), (x, 0.0, z),
               orientation=(math.cos(turn / 2), 0.0, math.sin(turn / 2), 0.0),
               friction=friction)


def test_a_house_of_cards_stands():
    """Two A-frames of 0.4 m x 2 mm cards leaning 20 degrees (friction 0.7), a flat card across
    their tops and a third A-frame on it: 7 cards, standing still after the first second and
    asleep at the end, no card through another."""
    size, lean, mu = (0.4, 0.28, 0.002), math.radians(20.0), 0.7
    length, width, thick = size
    height = length * math.cos(lean) + thick * math.sin(lean)
    foot = 2 * (length * math.sin(lean) + thick * math.cos(lean))
    apart = foot + 0.02
    cards = []
    for k, x in enumerate((-apart / 2, apart / 2)):
        cards += [_card(f"A{k}{side}", x, 0.0, lean, side, size, mu) for side in (-1, 1)]
    top = height + thick / 2 + 2e-4
    cards.append(box("Flat", (apart / 2 + 0.02, width / 2, thick / 2), (0.0, 0.0, top),
                     friction=mu))
    cards += [_card(f"B{side}", 0.0, top + thick / 2 + 1e-4, lean, side, size, mu)
              for side in (-1, 1)]
    model, solver, state = world(*cards)
    track = []
    reports = run(solver, state, int(10.0 / DT), colliders=[ground(friction=mu)],
                  each=lambda f, s: track.append(s.body_x.copy()))
    track = np.array(track)
    second = int(1.0 / DT)
    assert np.linalg.norm(track[second:] - track[second], axis=2).max() < 1e-3
    assert max(r.overlap for r in reports) < thick  # no card passes through another
    assert track[-1, -1, 2] > top + 0.9 * height / 2  # the top frame still stands on the flat
    assert state.body_asleep.all()
