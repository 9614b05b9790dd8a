"""Pins and virtual springs: hard pins ride their animated rest positions exactly; soft pins,
attachments and keep-away springs settle where their closed-form equilibrium says."""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core.errors import PhysanimError
from physanim.core.springs import (SpringFrameInputs, SpringMeshBuilder, SpringMeshSettings,
                                   SpringMeshSolver, VirtualSprings)
from physanim.core.springs.implicit import BaraffWitkin
from physanim.tests.core.helpers import grid as _grid

G = 9.81
FPS = 24
DT = 1.0 / FPS


def _rotation_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _matrix(angle: float = 0.0, translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = _rotation_z(angle)
    m[:3, 3] = translation
    return m


def _animated_rest(rest: np.ndarray, frame: int) -> np.ndarray:
    """The rest shape waving and turning: a rigid motion plus a bend (pins need not be rigid)."""
    t = frame * DT
    moved = rest @ _rotation_z(0.4 * math.sin(3.0 * t)).T + [0.3 * t, 0.0, 0.2 * math.sin(5 * t)]
    moved[:, 2] += 0.1 * math.sin(4.0 * t) * rest[:, 0] ** 2
    return moved


# explicit substeps: this mesh's fastest mode is below sqrt(max_i sum_s k_s (1/m_i + 1/m_j)) =
# 245 rad/s (Gershgorin; one edge spring alone: 100 rad/s), so h omega <= 1.7 (SE) and 2.0 (RK4)
@pytest.mark.parametrize("integrator,substeps", [("IMPLICIT", 1), ("SYMPLECTIC_EULER", 6),
                                                 ("RK4", 5)])
def test_hard_pins_sit_on_their_animated_rest_positions_every_frame(integrator, substeps):
    """rest0 + s (rest1 - rest0) at s = 1 equals rest1 up to one rounding: 1e-15 m."""
    x, edges, tris, ls, lt, lv = _grid(5, 5)
    pin = np.zeros(len(x))
    pin[[0, 4, 12]] = 1.0  # two corners and the centre
    pin[[1, 2]] = 0.9995  # above HARD_PIN_WEIGHT: hard too
    hard = pin >= 0.999
    settings = SpringMeshSettings("Flag", stiffness=200.0, shear_stiffness=100.0)
    model = SpringMeshBuilder(settings, x, edges, tris, ls, lt, lv, pin_weight=pin).finalize(0)
    assert np.array_equal(model.pinned, hard)
    solver = SpringMeshSolver(model, integrator, substeps, frame_dt=DT, frame=0)
    state = model.state()
    for frame in range(12):
        rest0, rest1 = _animated_rest(x, frame), _animated_rest(x, frame + 1)
        solver.advance(state, SpringFrameInputs(frame, frame * DT, DT, rest0=rest0, rest1=rest1))
        np.testing.assert_allclose(state.x[hard], rest1[hard], rtol=0, atol=1e-15)
        np.testing.assert_allclose(state.v[hard], (rest1 - rest0)[hard] / DT, rtol=1e-12)
    assert np.abs(state.x[~hard] - rest1[~hard]).max() > 1e-3  # the rest is free to swing


def _one_vertex(name: str = "Bob", mass: float = 0.1):
    settings = SpringMeshSettings(name, mass=mass, bend_mode="NONE", shear_stiffness=0.0,
                                  drag=0.0)
    return SpringMeshBuilder(settings, [[0.0, 0.0, 1.0]], np.zeros((0, 2)), np.zeros((0, 3)),
                             pin_weight=[0.5])


def test_soft_pin_sags_by_m_g_over_weight_times_stiffness():
    """A weight-0.5 pin is a zero-rest-length spring of 0.5 k: equilibrium sag m g / (0.5 k).
    Critically damped (c = 2 sqrt(0.5 k m) after weighting); after 2 s the transient is
    e^{-omega t} = e^{-45}. Backward Euler's fixed point is the exact equilibrium; the solve
    stops at residual 1e-3 of h |m g|, i.e. a force error <= 1e-3 m g: relative 1e-3 of the sag.
    """
    k, m, w = 100.0, 0.1, 0.5
    builder = _one_vertex(mass=m)
    builder.add_virtual(VirtualSprings("PIN", np.array([0]), np.array([w]), 0.0, k,
                                       2.0 * math.sqrt(w * k * m) / w))
    model = builder.finalize(0)
    assert not model.pinned[0]  # weight 0.5 is soft
    solver = SpringMeshSolver(model, "IMPLICIT", 1, frame_dt=DT)
    state = model.state()
    for frame in range(48):
        solver.advance(state, SpringFrameInputs(frame, frame * DT, DT))
    sag = m * G / (w * k)
    np.testing.assert_allclose(state.x[0], [0.0, 0.0, 1.0 - sag],
                               atol=BaraffWitkin.TOLERANCE * sag)


def test_soft_pin_pulls_a_displaced_vertex_back_to_its_moving_rest_position():
    """No gravity; the rest position a(t) moves at constant velocity u. The zero-length spring
    pulls with f = -k_eff (x - a) - c_eff (v - u), so e = x - a obeys a critically damped
    oscillator: e = (e0 + (omega e0) t) e^{-omega t}, shrinking monotonically, and x -> a, v -> u
    with no lag. RK4 at omega h = 0.23: relative error ~(omega h)^4 / 120 per step."""
    k, m, w = 100.0, 0.1, 0.5
    builder = _one_vertex(mass=m)
    builder.add_virtual(VirtualSprings("PIN", np.array([0]), np.array([w]), 0.0, k,
                                       2.0 * math.sqrt(w * k * m) / w))
    model = builder.finalize(0)
    solver = SpringMeshSolver(model, "RK4", 4, frame_dt=DT)
    state = model.state()
    state.x[0] += [0.2, -0.1, 0.05]
    u = np.array([0.5, 0.0, 0.0])
    rest = lambda f: model.rest_x + f * DT * u  # noqa: E731
    distance = [np.linalg.norm(state.x[0] - rest(0)[0])]
    for frame in range(48):
        solver.advance(state, SpringFrameInputs(frame, frame * DT, DT, gravity=(0, 0, 0),
                                                rest0=rest(frame), rest1=rest(frame + 1)))
        distance.append(np.linalg.norm(state.x[0] - rest(frame + 1)[0]))
    # the distance shrinks every frame (critical damping: no overshoot) until rounding (1e-12)
    distance = np.array(distance)
    assert np.all(np.diff(distance)[distance[:-1] > 1e-12] < 0.0)
    assert distance[-1] < 1e-6 * distance[0] + 1e-9
    np.testing.assert_allclose(state.v[0], u, atol=1e-6)


@pytest.mark.parametrize("integrator", ["IMPLICIT", "BDF2"])
def test_a_soft_pin_moving_at_constant_speed_is_followed_without_a_step_of_lag(integrator):
    """One step per frame, no gravity, the rest position moving at u: the implicit steps take
    the springs' pull at each step's end, where the anchor then is, so the vertex settles on
    it (v -> u, x -> a with no lag). Pulled from where the anchor was at the step's start, it
    trailed it for good (10 mm with BDF2, 14 mm with backward Euler; u h is 21 mm). The
    one-vertex solve is exact; after 4 s the critically damped transient (omega = 32 rad/s) is
    gone."""
    k, m, w = 100.0, 0.1, 0.5
    builder = _one_vertex(mass=m)
    builder.add_virtual(VirtualSprings("PIN", np.array([0]), np.array([w]), 0.0, k,
                                       2.0 * math.sqrt(w * k * m) / w))
    model = builder.finalize(0)
    solver = SpringMeshSolver(model, integrator, 1, frame_dt=DT)
    state = model.state()
    u = np.array([0.5, 0.0, 0.0])
    rest = lambda f: model.rest_x + f * DT * u  # noqa: E731
    for frame in range(96):
        solver.advance(state, SpringFrameInputs(frame, frame * DT, DT, gravity=(0, 0, 0),
                                                rest0=rest(frame), rest1=rest(frame + 1)))
    lag = np.linalg.norm(state.x[0] - rest(96)[0])
    assert lag < 1e-3 * np.linalg.norm(u) * DT, f"{lag * 1000:.3f} mm behind the anchor"
    np.testing.assert_allclose(state.v[0], u, atol=1e-6)


def test_attached_vertices_follow_a_moving_target():
    """ATTACH: each vertex is tied (zero rest length) to the target-local point it sat on at the
    start frame. When the target moves rigidly from M0 to M1 and stays, the internal springs are
    at rest in M1 M0^-1 (rest) and every virtual spring is slack there: that is the equilibrium.
    Damped springs + drag settle it; after 3 s held, 1e-4 m."""
    x, edges, tris, ls, lt, lv = _grid(4, 4, 0.5)
    settings = SpringMeshSettings("Patch", mass=0.2, stiffness=300.0, shear_stiffness=150.0,
                                  drag=0.5)
    builder = SpringMeshBuilder(settings, x, edges, tris, ls, lt, lv)
    attached = np.array([0, 3, 12, 15, 5])
    builder.add_virtual(VirtualSprings("ATTACH", attached, np.ones(len(attached)), 0.0, 200.0,
                                       5.0, target="Hand"))
    model = builder.finalize(0)
    solver = SpringMeshSolver(model, "IMPLICIT", 2, frame_dt=DT)
    state = model.state()
    m0 = _matrix(0.3, (1.0, -0.5, 0.2))
    m1 = _matrix(1.5, (0.2, 0.8, 1.0))
    moving = 24
    for frame in range(moving + 72):
        s0, s1 = min(frame / moving, 1.0), min((frame + 1) / moving, 1.0)
        # linear blend of two rigid motions is not rigid: only the end pose matters here
        ma = _matrix(0.3 + 1.2 * s0, (1.0 - 0.8 * s0, -0.5 + 1.3 * s0, 0.2 + 0.8 * s0))
        mb = _matrix(0.3 + 1.2 * s1, (1.0 - 0.8 * s1, -0.5 + 1.3 * s1, 0.2 + 0.8 * s1))
        if frame == 0:
            assert np.allclose(ma, m0)
        solver.advance(state, SpringFrameInputs(frame, frame * DT, DT, gravity=(0, 0, 0),
                                                targets={"Hand": (ma, mb)}))
    expected = (x - m0[:3, 3]) @ m0[:3, :3] @ m1[:3, :3].T + m1[:3, 3]  # M1 M0^-1 x
    np.testing.assert_allclose(state.x, expected, atol=1e-4)


def test_distance_springs_hold_vertices_at_their_rest_length_from_the_target():
    """DISTANCE: loose vertices (no other springs, no gravity) settle on the sphere of radius
    rest_length around the target's origin, each along its own starting direction."""
    rng = np.random.default_rng(11)
    directions = rng.normal(size=(6, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    centre = np.array([0.5, -0.2, 1.0])
    radius = rng.uniform(0.5, 2.0, size=6)
    x = centre + radius[:, None] * directions
    settings = SpringMeshSettings("Orbit", mass=0.6, bend_mode="NONE", shear_stiffness=0.0)
    builder = SpringMeshBuilder(settings, x, np.zeros((0, 2)), np.zeros((0, 3)))
    builder.add_virtual(VirtualSprings("DISTANCE", np.arange(6), np.ones(6), 1.25, 50.0, 4.0,
                                       target="Ball"))
    model = builder.finalize(0)
    solver = SpringMeshSolver(model, "IMPLICIT", 1, frame_dt=DT)
    state = model.state()
    target = _matrix(0.7, centre)  # the rotation must not matter, only the origin
    for frame in range(72):
        solver.advance(state, SpringFrameInputs(frame, frame * DT, DT, gravity=(0, 0, 0),
                                                targets={"Ball": (target, target)}))
    # Without gravity the implicit solve judges its residual against h |M| * 1 m/s^2 and stops
    # at 1e-3 of it: a force error up to 1e-3 |M| N, i.e. 1e-3 |M| / k [m] off the equilibrium
    # radius (the springs' stiffness holds it there).
    solve = BaraffWitkin.TOLERANCE * np.linalg.norm(model.vertex_mass) / 50.0
    offset = state.x - centre
    np.testing.assert_allclose(np.linalg.norm(offset, axis=1), 1.25, atol=solve)
    # Sideways nothing restores a vertex: the solve's velocity errors (up to 1e-3 of |b|, large
    # in the first frames) integrate there, ~1 cm over 3 s. The pull itself is radial: each
    # vertex stays near its own starting direction (0.05 rad).
    np.testing.assert_allclose(offset / np.linalg.norm(offset, axis=1, keepdims=True),
                               directions, atol=0.05)


def test_virtual_spring_target_without_transform_is_an_error_naming_it():
    builder = _one_vertex("Bob")
    builder.add_virtual(VirtualSprings("ATTACH", np.array([0]), np.ones(1), target="Ghost"))
    solver = SpringMeshSolver(builder.finalize(0), "IMPLICIT", 1, frame_dt=DT)
    with pytest.raises(PhysanimError, match=r'spring mesh "Bob" at frame 3: .*"Ghost"'):
        solver.advance(solver.model.state(), SpringFrameInputs(3, 3 * DT, DT))


def test_virtual_springs_validate_their_settings():
    with pytest.raises(ValueError, match="PIN spring group needs no target"):
        VirtualSprings("PIN", np.array([0]), np.ones(1), target="X")
    with pytest.raises(ValueError, match="needs a target"):
        VirtualSprings("ATTACH", np.array([0]), np.ones(1))
    with pytest.raises(ValueError, match=r"stiffness must be finite and >= 0 \(got -1"):
        VirtualSprings("PIN", np.array([0]), np.ones(1), stiffness=-1.0)
    with pytest.raises(ValueError, match="mode must be one of"):
        VirtualSprings("GLUE", np.array([0]), np.ones(1))
