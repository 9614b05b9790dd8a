"""Analytic colliders: no tunnelling (through a thin sheet: the analytic plane and a triangle
mesh), moving colliders, exact bounce normals on transformed spheres and boxes, and fast-spinning
colliders that never swallow a particle.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core import contact as coll
from physanim.core.contact import ColliderFrame
from physanim.core.particles import EmitterFrame, EmitterSettings, FrameInputs, ParticleSolver
from physanim.core.contact import SKIN
from physanim.tests.core.helpers import (
    mesh_collider, particle_model as _model, place as _place, rotation as _rotation, sheet,
    translation as _translate,
)

G = 9.81
FPS = 24
DT = 1.0 / FPS


def _inputs(frame, colliders, gravity=(0.0, 0.0, -G), dt=DT):
    return FrameInputs(frame=frame, t0=frame * dt, frame_dt=dt, gravity=gravity,
                       emitters=[EmitterFrame(active=False)], colliders=colliders)


def _scale(x, y, z):
    return np.diag([x, y, z, 1.0])


def _local(m, x):
    inv = np.linalg.inv(m)
    return x @ inv[:3, :3].T + inv[:3, 3]


# -- tunnelling ---------------------------------------------------------------------------------

def _thin_sheet(kind, k, speed):
    """A frictionless sheet of zero thickness over |x|, |y| <= 5 in z = 0 and where to shoot at
    it: (collider, xy (n, 2) [m], tilt (n, 2): the shots' horizontal velocity [m/s])."""
    rng = np.random.default_rng(0)
    if kind == "PLANE":
        plane = _scale(5.0, 5.0, 1.0)
        collider = ColliderFrame("Glass", "PLANE", plane, plane, restitution=k, friction=0.0)
        ticks = np.linspace(-4.5, 4.5, 7)
        xy = np.array([(x, y) for x in ticks for y in ticks])
        tilt = rng.uniform(-0.2, 0.2, size=(len(xy), 2)) * speed  # oblique, still landing on it
        return collider, xy, tilt
    verts, tris = sheet(9, 10.0)  # vertices every 1.25 m
    collider = mesh_collider("Glass", verts, tris, restitution=k, friction=0.0)
    n = 60
    xy = rng.uniform(-4.5, 4.5, size=(n, 2))
    xy[:20] = np.round(xy[:20] / 1.25) * 1.25  # exactly over vertices
    xy[20:30, 0] = np.round(xy[20:30, 0] / 1.25) * 1.25  # exactly over edges
    tilt = rng.uniform(-0.2, 0.2, size=(n, 2)) * speed
    tilt[:30] = 0.0  # straight down onto the vertices and edges
    return collider, xy, tilt


@pytest.mark.parametrize("kind,speed", [("PLANE", 100.0), ("PLANE", 1000.0), ("MESH", 100.0)])
def test_fast_particles_never_cross_a_thin_sheet(kind, speed):
    # One sub-step per frame: a 1000 m/s particle moves 42 m per step across a sheet of zero
    # thickness (the analytic plane, or a triangle mesh: there also straight down onto its shared
    # edges and vertices, where a segment could slip between two triangles). Continuous detection
    # must bounce every particle aimed at the sheet (from either side) and let the ones aimed
    # beside its bounded square (|x|, |y| > 5) pass.
    k = 0.5
    collider, xy, tilt = _thin_sheet(kind, k, speed)
    n = len(xy)
    above = np.column_stack([xy, np.full(n, 1.0)])
    below = np.column_stack([xy, np.full(n, -1.0)])
    beside = np.column_stack([xy + 20.0, np.full(n, 1.0)])
    v_down = np.column_stack([tilt, np.full(n, -speed)])
    v_up = np.column_stack([tilt, np.full(n, speed)])
    model = _model(EmitterSettings("Shot"))
    state = model.state()
    _place(state, above, v_down)
    _place(state, below, v_up)
    _place(state, beside, v_down)
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps=1)
    report = solver.advance(state, _inputs(0, [collider]))
    z = state.particle_x[:, 2]
    vz = state.particle_v[:, 2]
    assert report.collisions == 2 * n
    assert np.all(z[:n] > 0.0) and np.all(z[n:2 * n] < 0.0)
    assert np.all(z[2 * n:] < -speed * DT / 2)  # beside the square: no collider there
    # reflected with restitution, then gravity acts for the rest of the step:
    # vz = k (speed +- g t_hit) -+ g (h - t_hit), so |vz - k speed| <= (1 + k) g h
    np.testing.assert_allclose(vz[:n], k * speed, rtol=0, atol=(1 + k) * G * DT)
    np.testing.assert_allclose(vz[n:2 * n], -k * speed, rtol=0, atol=(1 + k) * G * DT)
    np.testing.assert_allclose(state.particle_v[:2 * n, :2], np.vstack([tilt, tilt]))  # mu = 0
    for f in range(1, 4):  # they fly away and stay on their side
        solver.advance(state, _inputs(f, [collider]))
        assert np.all(state.particle_x[:n, 2] > 0.0)
        assert np.all(state.particle_x[n:2 * n, 2] < 0.0)


@pytest.mark.parametrize("speed", [100.0, 1000.0])
def test_oblique_fast_particles_stay_above_ground(speed):
    rng = np.random.default_rng(1)
    n = 200
    d = rng.normal(size=(n, 3))
    d[:, 2] = -np.abs(d[:, 2]) - 0.2
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    ground = ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4), restitution=0.8,
                           friction=0.3)
    model = _model(EmitterSettings("Shot"))
    state = model.state()
    _place(state, rng.uniform([-1, -1, 0.01], [1, 1, 2], size=(n, 3)), d * speed)
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps=1)
    for f in range(5):
        solver.advance(state, _inputs(f, [ground]))
        assert np.all(state.particle_x[:, 2] >= 0.0)


# -- moving colliders ---------------------------------------------------------------------------

@pytest.mark.parametrize("k", [0.0, 0.5, 1.0])
def test_rising_ground_hits_resting_particle(k):
    # Relative to the ground the particle approaches at -V; it leaves at +k V, i.e. (1 + k) V in
    # the world. The ground's velocity is a central difference of a linear translation: exact to
    # rounding (~1e-11 of V). The particle must end above the ground.
    speed = 5.0
    model = _model(EmitterSettings("Pebble"))
    state = model.state()
    _place(state, [0.3, -0.2, 0.1], [0.0, 0.0, 0.0])
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps=1)
    for f in range(4):
        m0, m1 = _translate(z=speed * f * DT), _translate(z=speed * (f + 1) * DT)
        ground = ColliderFrame("Piston", "HALF_SPACE", m0, m1, restitution=k, friction=0.0)
        report = solver.advance(state, _inputs(f, [ground], gravity=(0, 0, 0)))
        if f == 0:
            assert report.collisions == 1
        assert state.particle_x[0, 2] >= speed * (f + 1) * DT
        np.testing.assert_allclose(state.particle_v[0], [0.0, 0.0, (1.0 + k) * speed],
                                   atol=1e-8 * speed)
    np.testing.assert_allclose(state.particle_x[0, :2], [0.3, -0.2])


def test_particle_rides_rising_platform():
    # Inelastic (k = 0) platform rising at V under gravity: once it has caught the particle, the
    # particle rests on it: vz == V (contact cancels gravity), never below it, and no further
    # than the contact distance above it.
    speed = 1.0
    model = _model(EmitterSettings("Pebble"))
    state = model.state()
    _place(state, [0.0, 0.0, 0.05], [0.0, 0.0, 0.0])
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps=2)
    for f in range(48):
        m0, m1 = _translate(z=speed * f * DT), _translate(z=speed * (f + 1) * DT)
        platform = ColliderFrame("Lift", "HALF_SPACE", m0, m1, restitution=0.0, friction=0.5)
        solver.advance(state, _inputs(f, [platform]))
        gap = state.particle_x[0, 2] - speed * (f + 1) * DT
        assert gap >= 0.0
        if f >= 6:
            assert gap <= 1e-3
            assert state.particle_v[0, 2] == pytest.approx(speed, abs=1e-9)



def test_a_still_collider_keeps_one_path_until_it_changes():
    # A still collider's next interval reuses its path; any change (a move, a property, the
    # interval's length) makes a new one.
    paths = coll.ColliderPaths()
    still = ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4), restitution=0.3)
    first = paths.path(still, DT)
    again = ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4), restitution=0.3)
    assert paths.path(again, DT) is first
    moved = _translate(z=0.01)
    for changed, dt in [(ColliderFrame("Ground", "HALF_SPACE", np.eye(4), moved, 0.3), DT),
                        (ColliderFrame("Ground", "HALF_SPACE", moved, moved, 0.3), DT),
                        (ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4), 0.4), DT),
                        (ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4), 0.3,
                                       thickness=0.01), DT),
                        (ColliderFrame("Ground", "PLANE", np.eye(4), np.eye(4), 0.3), DT),
                        (still, 0.5 * DT)]:
        made = paths.path(changed, dt)
        assert made is not first and made.frame is changed and made.frame_dt == dt
        first = paths.path(still, DT)


def test_a_still_mesh_keeps_one_path_and_a_checkpoint_leaves_it_out():
    """A mesh standing still keeps its path (its hierarchy and grid) while its frame stays the
    same, vertex for vertex; moving, deforming or another mesh makes a new one, and a mesh
    moving over its interval is never kept. Pickled (a checkpoint), the paths leave the kept
    mesh out: the next interval makes it again, answering the same."""
    import pickle

    verts = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    tris = np.array([[0, 1, 2], [0, 2, 3]])

    def mesh(v0, v1=None, m1=None):
        return ColliderFrame("Floor", "MESH", np.eye(4), np.eye(4) if m1 is None else m1, 0.3,
                             vertices0=v0, vertices1=v0 if v1 is None else v1, triangles=tris)
    paths = coll.ColliderPaths()
    first = paths.path(mesh(verts), DT)
    assert paths.path(mesh(verts.copy()), DT) is first
    lifted = verts + [0.0, 0.0, 0.01]
    for changed in (mesh(lifted), mesh(verts, lifted), mesh(verts, m1=_translate(z=0.01))):
        made = paths.path(changed, DT)
        assert made is not first and made.frame is changed
        assert paths.path(changed, DT) is not made or made.still
        first = paths.path(mesh(verts), DT)
    saved = pickle.loads(pickle.dumps(paths))
    assert "Floor" in paths._kept and "Floor" not in saved._kept  # (its hierarchy is saved)
    again = saved.path(mesh(verts), DT)
    assert again.reusable and saved.path(mesh(verts), DT) is again
    x0 = np.array([[0.2, 0.1, 0.5], [3.0, 3.0, 0.5]])
    x1 = np.array([[0.2, 0.1, -0.5], [3.0, 3.0, -0.5]])
    hits = [p.first_hits(x0, x1, np.zeros(2), np.ones(2)) for p in (first, again)]
    assert hits[0].index.tolist() == hits[1].index.tolist() == [0]
    assert np.array_equal(hits[0].point, hits[1].point)


def test_particle_rides_a_platform_that_waits_rises_and_stops():
    # Still for 6 frames (one path kept), rising at 1 m/s for 12, then still again: the
    # particle rides it up, flies on when it stops (about 5 cm up and back) and rests on it.
    model = _model(EmitterSettings("Pebble"))
    state = model.state()
    _place(state, [0.0, 0.0, 0.01], [0.0, 0.0, 0.0])
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps=2)
    height = [min(max(f - 6, 0), 12) * DT for f in range(41)]  # the platform at frame f
    for f in range(40):
        lift = ColliderFrame("Lift", "HALF_SPACE", _translate(z=height[f]),
                             _translate(z=height[f + 1]), restitution=0.0, friction=0.5)
        solver.advance(state, _inputs(f, [lift]))
        gap = state.particle_x[0, 2] - height[f + 1]
        assert gap >= 0.0, f"frame {f}: {gap} below the platform"
        if 8 <= f < 18 or f >= 36:
            assert gap <= 2e-3, f"frame {f}: {gap} above the platform"
    assert abs(state.particle_v[0, 2]) < 1e-9

# -- exact bounces on transformed shapes --------------------------------------------------------

def _transformed_collider():
    # rotated, non-uniformly scaled and moved: an ellipsoid / a brick
    return (_translate(0.5, -1.0, 2.0) @ _rotation([1.0, 2.0, 0.5], 0.9)
            @ _scale(2.0, 0.7, 1.3))


def _expected_bounce(m, target_local, normal_local, k, start_distance, speed):
    """A particle aimed at world point M target_local along -u (u outward, not tangent): hit
    point, world normal (inverse-transpose of M), and the reflection v' = v - (1 + k)(v.n)n."""
    lin = m[:3, :3]
    hit = lin @ target_local + m[:3, 3]
    n = np.linalg.inv(lin).T @ normal_local
    n /= np.linalg.norm(n)
    u = n + 0.3 * np.cross(n, [0.0, 0.0, 1.0])  # an oblique approach from outside
    u /= np.linalg.norm(u)
    x0 = hit + start_distance * u
    v = -speed * u
    v_out = v - (1.0 + k) * (v @ n) * n
    return x0, v, hit, n, v_out


@pytest.mark.parametrize("shape,target,normal", [
    ("SPHERE", np.array([0.6, 0.0, 0.8]), np.array([0.6, 0.0, 0.8])),
    ("SPHERE", np.array([-2.0, 1.0, -2.0]) / 3.0, np.array([-2.0, 1.0, -2.0]) / 3.0),
    ("BOX", np.array([1.0, 0.2, -0.3]), np.array([1.0, 0.0, 0.0])),
    ("BOX", np.array([-0.4, 0.5, -1.0]), np.array([0.0, 0.0, -1.0])),
    ("BOX", np.array([0.1, -1.0, 0.6]), np.array([0.0, -1.0, 0.0])),
])
def test_bounce_normal_on_transformed_shape(shape, target, normal):
    # No gravity, static collider: the flight is straight, so detection, normal and reflection
    # are exact up to rounding. After one frame: v' = v - (1 + k)(v.n) n with n the analytic
    # normal M^-T n_local, and x = hit + SKIN n + v' (dt - t_hit).
    k, speed = 0.6, 12.0
    m = _transformed_collider()
    x0, v, hit, n, v_out = _expected_bounce(m, target, normal, k, 0.2, speed)
    t_hit = 0.2 / speed
    assert t_hit < DT
    collider = ColliderFrame("Rock", shape, m, m, restitution=k, friction=0.0)
    model = _model(EmitterSettings("Shot"))
    state = model.state()
    _place(state, x0, v)
    report = ParticleSolver(model, "RK4").advance(state, _inputs(0, [collider], gravity=(0, 0, 0)))
    assert report.collisions == 1
    np.testing.assert_allclose(state.particle_v[0], v_out, atol=1e-9 * speed)
    np.testing.assert_allclose(state.particle_x[0], hit + SKIN * n + v_out * (DT - t_hit),
                               atol=1e-9)


def _outside(shape, local):
    if shape == "SPHERE":
        return np.linalg.norm(local, axis=1) >= 1.0
    return np.abs(local).max(axis=1) >= 1.0


@pytest.mark.parametrize("shape", ["SPHERE", "BOX"])
def test_rain_on_transformed_shape_never_ends_inside(shape):
    # Particles from all around, aimed at the collider, fast and slow, with gravity; checked in
    # the collider's local space after every frame.
    m = _transformed_collider()
    rng = np.random.default_rng(3)
    n = 400
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    centre = m[:3, 3]
    x0 = centre + 4.0 * d
    v = -d * rng.uniform(1.0, 200.0, size=(n, 1))
    collider = ColliderFrame("Rock", shape, m, m, restitution=0.4, friction=0.3)
    model = _model(EmitterSettings("Rain"))
    state = model.state()
    _place(state, x0, v)
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps=1)
    hits = 0
    for f in range(30):
        hits += solver.advance(state, _inputs(f, [collider])).collisions
        local = _local(m, state.particle_x)
        assert np.all(_outside(shape, local)), f"frame {f}: particle inside the {shape}"
    assert hits >= n // 2  # aimed at the collider (gravity bends the slow ones away)


@pytest.mark.parametrize("shape", ["BOX", "SPHERE"])
def test_fast_spinning_collider_never_swallows_particles(shape):
    # A flat paddle (non-uniform scale) spinning 90 degrees per frame about a tilted axis, with
    # particles raining on it: no particle is inside at the end of any frame (local space of
    # the frame-end matrix).
    scale = _scale(3.0, 0.4, 0.5)
    centre = _translate(0.0, 0.0, 1.0)
    axis = [0.2, -0.1, 1.0]
    step = math.pi / 2
    rng = np.random.default_rng(4)
    n = 600
    x0 = np.column_stack([rng.uniform(-3, 3, n), rng.uniform(-3, 3, n), rng.uniform(1.5, 4, n)])
    model = _model(EmitterSettings("Rain"))
    state = model.state()
    _place(state, x0, np.zeros((n, 3)))
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps=1)
    hits = 0
    for f in range(36):
        m0 = centre @ _rotation(axis, step * f) @ scale
        m1 = centre @ _rotation(axis, step * (f + 1)) @ scale
        paddle = ColliderFrame("Paddle", shape, m0, m1, restitution=0.3, friction=0.4)
        hits += solver.advance(state, _inputs(f, [paddle])).collisions
        local = _local(m1, state.particle_x)
        assert np.all(_outside(shape, local)), f"frame {f}: particle inside the spinning {shape}"
    assert hits > 50


def test_respond_records_each_hit_for_the_spring_solver():
    """``respond`` returns every hit particle's first collision as Contacts: a particle falling
    through a ground rising at 1 m/s is recorded with the ground's normal and velocity, its
    collider's restitution and friction, the normal velocity change of its bounce, and a landing
    point SKIN above the surface where the ground has carried it at the sub-step's end; a
    particle that misses is not recorded."""

    m0, m1 = np.eye(4), np.eye(4)
    m1[2, 3] = DT  # the ground rises 1 m/s
    ground = ColliderFrame("Ground", "HALF_SPACE", m0, m1, restitution=0.25, friction=0.6)
    paths = coll.ColliderPaths().of([ground], DT)
    x0 = np.array([[0.0, 0.0, 0.05], [2.0, 0.0, 3.0]])
    v0 = np.array([[0.0, 0.0, -4.0], [0.0, 0.0, -1.0]])
    x1 = x0 + DT * v0
    first = coll.respond(paths, x0, x1, v0, v0.copy(), 0.0, 1.0, DT, 0.01).first
    np.testing.assert_array_equal(first.index, [0])
    np.testing.assert_allclose(first.normal, [[0.0, 0.0, 1.0]], atol=1e-12)
    np.testing.assert_allclose(first.surface_velocity, [[0.0, 0.0, 1.0]], atol=1e-9)
    np.testing.assert_allclose(first.restitution, [0.25])
    np.testing.assert_allclose(first.friction, [0.6])
    np.testing.assert_allclose(first.point[0, 2], DT + SKIN, atol=1e-9)
    # it met the ground at 5 m/s relative to it and left at 0.25 of that: a 6.25 m/s change
    np.testing.assert_allclose(first.impulse, [5.0 * 1.25], rtol=1e-9)


def test_a_response_that_hits_nothing_gives_back_the_paths_it_owns_and_copies_the_others():
    """``respond(own=True)``: the caller's integrated arrays come back as they are when no path
    enters a collider (a particle step's common case), copied when not owned; a hit corrects
    them as ever."""
    ground = ColliderFrame("Ground", "HALF_SPACE", np.eye(4), np.eye(4), restitution=0.5)
    paths = coll.ColliderPaths().of([ground], DT)
    x0 = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 2.0]])
    v0 = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 0.0]])
    x1, v1 = x0 + DT * v0, v0.copy()
    owned = coll.respond(paths, x0, x1, v0, v1, 0.0, 1.0, DT, 0.01, own=True)
    assert owned.x is x1 and owned.v is v1 and owned.count == 0 and len(owned.first) == 0
    copied = coll.respond(paths, x0, x1, v0, v1, 0.0, 1.0, DT, 0.01)
    assert copied.x is not x1 and np.array_equal(copied.x, x1) and np.array_equal(copied.v, v1)
    falling = np.array([[0.0, 0.0, 0.01], [1.0, 0.0, 2.0]])
    v_fall = np.array([[0.0, 0.0, -2.0], [0.0, 0.0, 0.0]])
    hit = coll.respond(paths, falling, falling + DT * v_fall, v_fall, v_fall.copy(), 0.0, 1.0,
                       DT, 0.01, own=True)
    assert hit.count == 1 and hit.v[0, 2] == pytest.approx(1.0)  # bounced at e = 0.5
    assert list(hit.first.index) == [0]
