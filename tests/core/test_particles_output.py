"""Render arrays of one emitter: shapes, dtypes, life curves and velocity-aligned instances."""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core.curves import LifeCurve
from physanim.core.errors import PhysanimError
from physanim.core.particles import (
    EmitterFrame, EmitterSettings, FrameInputs, ParticleSolver, emitter_arrays,
)
from physanim.tests.core.helpers import particle_model as _model

KEYS = {
    "id": (np.int32, ()), "position": (np.float32, (3,)), "velocity": (np.float32, (3,)),
    "age": (np.float32, ()), "life": (np.float32, ()), "size": (np.float32, ()),
    "color": (np.float32, (4,)),
}
# only with shape-from-velocity (stretch > 0); round particles are scaled by ``size``
STRETCH_KEYS = {"instance_scale": (np.float32, (3,)), "instance_rotation": (np.float32, (3,))}


def _place(state, x, v, emitter=0, age=0.0, life=1.0, size=0.1):
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    v = np.atleast_2d(np.asarray(v, dtype=np.float64))
    n = len(x)
    return state.append(emitter, x, v, np.ones(n), np.broadcast_to(age, (n,)).astype(float),
                        np.full(n, life), np.full(n, size))


def test_arrays_shapes_dtypes_and_selection():
    model = _model(EmitterSettings("A", direction="RANDOM", seed=1),
                   EmitterSettings("B", direction="RANDOM", seed=2))
    state = model.state()
    solver = ParticleSolver(model)
    frames = [EmitterFrame(rate=7, lifetime=1.0), EmitterFrame(rate=3, lifetime=1.0)]
    for f in range(5):
        solver.advance(state, FrameInputs(f, f / 24, 1 / 24, emitters=frames))
    for emitter, count in ((0, 35), (1, 15)):
        out = emitter_arrays(model, state, emitter)
        assert set(out) == set(KEYS)
        for key, (dtype, tail) in KEYS.items():
            assert out[key].dtype == dtype, key
            assert out[key].shape == (count,) + tail, key
            assert out[key].flags.c_contiguous, key
        sel = state.particle_emitter == emitter
        np.testing.assert_array_equal(out["id"], state.particle_id[sel])
        np.testing.assert_allclose(out["position"], state.particle_x[sel], rtol=1e-6)
        np.testing.assert_allclose(out["velocity"], state.particle_v[sel], rtol=1e-6)


def test_empty_emitter_gives_empty_arrays():
    model = _model(EmitterSettings("Idle"))
    out = emitter_arrays(model, model.state(), 0)
    for key, (dtype, tail) in KEYS.items():
        assert out[key].shape == (0,) + tail and out[key].dtype == dtype


def test_color_and_size_follow_life_curves():
    # Curves are linear between stops over the life fraction age / life: at half life the
    # colour is the midpoint of red-opaque and blue-transparent, the size factor 1 of 2 -> 0.
    color = LifeCurve((0.0, 1.0), ((1.0, 0.0, 0.0, 1.0), (0.0, 0.0, 1.0, 0.0)))
    size = LifeCurve((0.0, 0.5, 1.0), ((2.0,), (1.0,), (0.0,)))
    model = _model(EmitterSettings("Fade", color=color, size=size))
    state = model.state()
    life = 2.0
    ages = np.array([0.0, 0.5, 1.0, 1.5, 2.0])
    _place(state, np.zeros((5, 3)), np.zeros((5, 3)), age=ages, life=life, size=0.1)
    out = emitter_arrays(model, state, 0)
    frac = ages / life
    np.testing.assert_allclose(out["color"], np.column_stack(
        [1 - frac, np.zeros(5), frac, 1 - frac]), atol=1e-7)
    np.testing.assert_allclose(out["color"][2], [0.5, 0.0, 0.5, 0.5], atol=1e-7)
    np.testing.assert_allclose(out["size"], 0.1 * np.array([2.0, 1.5, 1.0, 0.5, 0.0]), atol=1e-7)
    assert not set(STRETCH_KEYS) & set(out)  # no stretch: the renderer scales by size


def test_constant_curves_give_their_value_at_any_age():
    # several stops of one value, a single stop, and a curve whose stops differ only in one
    # channel (not constant): each as np.interp gives it, whatever the life fraction
    t = np.array([-0.5, 0.0, 0.3, 1.0, 2.0])
    for curve, constant in ((LifeCurve((0.0, 0.4, 1.0), ((0.2, 0.3),) * 3), True),
                            (LifeCurve.constant(0.7, 0.1, 0.2, 1.0), True),
                            (LifeCurve((0.0, 1.0), ((1.0, 0.5), (1.0, 0.6))), False)):
        assert curve.is_constant is constant
        expected = np.column_stack([np.interp(t, curve.positions, np.array(curve.values)[:, c])
                                    for c in range(curve.channels)])
        np.testing.assert_array_equal(curve.evaluate(t), expected)
        single = curve.evaluate(t, np.float32)
        assert single.dtype == np.float32 and single.flags.c_contiguous
        np.testing.assert_array_equal(single, expected.astype(np.float32))
    model = _model(EmitterSettings("Plain", size=LifeCurve((0.0, 1.0), ((1.5,), (1.5,)))))
    state = model.state()
    _place(state, np.zeros((3, 3)), np.zeros((3, 3)), age=np.array([0.0, 1.0, 5.0]), life=2.0,
           size=0.1)
    out = emitter_arrays(model, state, 0)
    np.testing.assert_allclose(out["size"], 0.15, rtol=1e-7)
    assert np.all(out["color"] == out["color"][0])


def _euler_xyz(angles):
    """Blender's Euler XYZ: R = Rz(c) Ry(b) Rx(a)."""
    a, b, c = angles
    rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    rz = np.array([[math.cos(c), -math.sin(c), 0], [math.sin(c), math.cos(c), 0], [0, 0, 1]])
    return rz @ ry @ rx


def test_stretch_aligns_instances_with_velocity():
    # Rotating local +Z by the Euler XYZ angles must give the velocity direction, and the
    # instance is scaled along it by 1 + stretch |v|.
    stretch = 0.2
    model = _model(EmitterSettings("Streak", stretch=stretch))
    state = model.state()
    rng = np.random.default_rng(3)
    v = rng.normal(size=(40, 3)) * 5.0
    v = np.vstack([v, [[0, 3.0, 0], [0, -2.0, 0], [0, 0, -1.0], [1e-3, 0, 0],
                       [0.0, 0.0, 0.0]]])
    n = len(v)
    _place(state, np.zeros((n, 3)), v, age=0.0, life=1.0, size=0.1)
    out = emitter_arrays(model, state, 0)
    for key, (dtype, tail) in STRETCH_KEYS.items():
        assert out[key].dtype == dtype and out[key].shape == (n,) + tail, key
    speed = np.linalg.norm(v, axis=1)
    for k in range(n - 1):
        z = _euler_xyz(out["instance_rotation"][k].astype(np.float64)) @ [0.0, 0.0, 1.0]
        np.testing.assert_allclose(z, v[k] / speed[k], atol=1e-6, err_msg=f"v = {v[k]}")
    np.testing.assert_array_equal(out["instance_rotation"][-1], 0.0)  # at rest: unrotated
    np.testing.assert_allclose(out["instance_scale"][:, :2], 0.1)
    np.testing.assert_allclose(out["instance_scale"][:, 2], 0.1 * (1 + stretch * speed),
                               rtol=1e-6)


def test_ids_beyond_int32_raise_naming_emitter_and_frame():
    model = _model(EmitterSettings("Huge"))
    state = model.state()
    state.next_id = 2 ** 31
    _place(state, np.zeros((1, 3)), np.zeros((1, 3)))
    with pytest.raises(PhysanimError) as info:
        emitter_arrays(model, state, 0, frame=412)
    err = info.value
    assert (err.obj, err.frame, err.kind) == ("Huge", 412, "emitter")
    message = str(err)
    assert message.startswith('emitter "Huge" at frame 412: ')
    assert "2,147,483,648" in message and "lower the rates" in message
    with pytest.raises(PhysanimError, match='^emitter "Huge": '):  # frame is optional
        emitter_arrays(model, state, 0)


def test_ids_at_int32_limit_are_fine():
    model = _model(EmitterSettings("Big"))
    state = model.state()
    state.next_id = 2 ** 31 - 1
    _place(state, np.zeros((1, 3)), np.zeros((1, 3)))
    assert emitter_arrays(model, state, 0, frame=1)["id"][0] == 2 ** 31 - 1
