"""Birth directions and mesh sources: the cone spread, VERTS vertex normals and VOLUME meshes of
either winding (or none). Statistical tolerances are 5 standard deviations (fixed seeds make
them deterministic anyway).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core.errors import PhysanimError
from physanim.core.particles import EmitterFrame, EmitterSettings, FrameInputs, ParticleSolver
from physanim.tests.core.helpers import particle_model as _model

DT = 1.0 / 24
ZERO_G = (0.0, 0.0, 0.0)


def _inputs(frame, emitters, gravity=ZERO_G, dt=DT):
    return FrameInputs(frame=frame, t0=frame * dt, frame_dt=dt, gravity=gravity,
                       emitters=list(emitters))


def _moved(angle=0.7, offset=(1.0, -2.0, 0.5)):
    """A rigid world matrix: rotation about z by ``angle`` and a translation."""
    c, s = math.cos(angle), math.sin(angle)
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:3, 3] = offset
    return m


def _cube():
    """Closed cube |x|, |y|, |z| <= 1 with outward-wound triangles."""
    verts = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    return verts, tris


def _outward(verts, tris):
    """Whether every triangle's normal points away from the mesh's centroid."""
    e1 = verts[tris[:, 1]] - verts[tris[:, 0]]
    e2 = verts[tris[:, 2]] - verts[tris[:, 0]]
    centre = verts[tris].mean(axis=1) - verts.mean(axis=0)
    return bool(np.all(np.einsum("ij,ij->i", np.cross(e1, e2), centre) > 0))


# -- cone spread ----------------------------------------------------------------------------------

@pytest.mark.parametrize("source", ["ORIGIN", "FACES"])
def test_spread_fills_the_cone_around_the_direction(source):
    # Directions are uniform on the spherical cap of half-angle a around the emission direction
    # (the rotated axis at the origin, the rotated face normal on a face): every angle is <= a,
    # cos(angle) is uniform on [cos a, 1], so the share beyond 0.9 a is
    # p = (cos 0.9a - cos a) / (1 - cos a) (~19 %), and the azimuth is uniform.
    spread, n = 0.4, 4000
    m = _moved()
    local_dir = np.array([1.0, 2.0, 2.0]) / 3.0
    if source == "ORIGIN":
        settings = EmitterSettings("Nozzle", direction="AXIS", axis=(1.0, 2.0, 2.0), seed=3)
        verts = None
    else:  # one triangle whose normal is (1, 2, 2) / 3
        verts = np.array([[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
        settings = EmitterSettings("Panel", source="FACES", triangles=[[0, 1, 2]],
                                   vertex_count=3, seed=3)
    model = _model(settings)
    state = model.state()
    ef = EmitterFrame(rate=n, speed=1.0, lifetime=100.0, spread=spread, verts0=verts,
                      matrix0=m, matrix1=m)
    ParticleSolver(model).advance(state, _inputs(0, [ef]))
    v = state.particle_v
    assert len(v) == n
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), 1.0, rtol=1e-12)
    axis = m[:3, :3] @ local_dir
    cos = v @ axis
    assert np.all(cos >= math.cos(spread) - 1e-12)  # inside the cone
    p = (math.cos(0.9 * spread) - math.cos(spread)) / (1.0 - math.cos(spread))
    rim = int(np.count_nonzero(cos < math.cos(0.9 * spread)))
    assert abs(rim - n * p) <= 5.0 * math.sqrt(n * p * (1.0 - p))  # reaches the rim
    sigma = (1.0 - math.cos(spread)) / math.sqrt(12.0 * n)
    assert abs(cos.mean() - (1.0 + math.cos(spread)) / 2.0) <= 5.0 * sigma
    # azimuth around the axis: 8 sectors of n/8 each
    e1 = np.cross(axis, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    sector = np.floor((np.arctan2(v @ e2, v @ e1) + math.pi) / (math.pi / 4)).astype(int) % 8
    counts = np.bincount(sector, minlength=8)
    assert np.all(np.abs(counts - n / 8) <= 5.0 * math.sqrt(n / 8 * 7 / 8))


# -- VERTS normals --------------------------------------------------------------------------------

def test_verts_emit_along_area_weighted_vertex_normals():
    # Tetrahedron (0,0,0), (2,0,0), (0,1,0), (0,0,1). Summing each adjacent face's cross product
    # (2 area x unit normal) gives the area-weighted normals in closed form:
    #   corner 0: faces -z (area 1), -y (area 1), -x (area 1/2)  ->  -(1, 2, 2) / 3
    #   corners 1, 2, 3: +x, +y, +z (the slanted face (1, 2, 2)/3 of area 3/2 cancels the rest).
    # An unweighted mean of face normals would give -(1, 1, 1)/sqrt 3 at corner 0.
    verts = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    tris = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    assert _outward(verts, tris)
    normals = np.array([[-1.0, -2.0, -2.0], [3.0, 0.0, 0.0], [0.0, 3.0, 0.0],
                        [0.0, 0.0, 3.0]]) / 3.0
    m = _moved()
    model = _model(EmitterSettings("Spiky", source="VERTS", direction="NORMAL", triangles=tris,
                                   vertex_count=4, seed=6))
    state = model.state()
    ef = EmitterFrame(rate=400, speed=1.0, lifetime=100.0, verts0=verts, matrix0=m, matrix1=m)
    ParticleSolver(model).advance(state, _inputs(0, [ef]))
    x, v = state.particle_x, state.particle_v
    birth = x - v * state.particle_age[:, None]  # straight flight since birth
    world = verts @ m[:3, :3].T + m[:3, 3]
    corner = np.linalg.norm(birth[:, None, :] - world[None], axis=2).argmin(axis=1)
    np.testing.assert_allclose(birth, world[corner], atol=1e-12)
    assert set(corner.tolist()) == {0, 1, 2, 3}
    np.testing.assert_allclose(v, normals[corner] @ m[:3, :3].T, atol=1e-12)


# -- VOLUME meshes --------------------------------------------------------------------------------

def test_volume_of_inside_out_cube_is_filled():
    # Flipped normals make the winding number -1 inside; the interior is the same.
    verts, tris = _cube()
    flipped = tris[:, ::-1].copy()
    assert not _outward(verts, flipped)
    m = _moved() @ np.diag([2.0, 0.5, 1.0, 1.0])
    model = _model(EmitterSettings("Inverted", source="VOLUME", triangles=flipped,
                                   vertex_count=8, seed=9))
    state = model.state()
    n = 2000
    ef = EmitterFrame(rate=n, speed=0.0, lifetime=100.0, verts0=verts, matrix0=m, matrix1=m)
    ParticleSolver(model).advance(state, _inputs(0, [ef]))
    inv = np.linalg.inv(m)
    local = state.particle_x @ inv[:3, :3].T + inv[:3, 3]
    assert len(local) == n
    assert np.all(np.abs(local) <= 1.0 + 1e-12)
    np.testing.assert_allclose(local.mean(axis=0), 0.0, atol=5 / math.sqrt(3 * n))
    assert np.abs(local).max() > 0.95


@pytest.mark.parametrize("tilted", [True, False])
def test_volume_of_flat_closed_mesh_raises_naming_emitter_and_frame(tilted):
    # A closed tetrahedron squashed into a plane (x + y + z = 0, or z = 0) passes the
    # closed-mesh check but encloses nothing: the bake stops with the emitter, the frame and
    # what to do.
    verts = np.array([[1.0, -1.0, 0.0], [0.0, 1.0, -1.0], [-1.0, 0.0, 1.0], [0.2, 0.3, -0.5]])
    if not tilted:
        verts = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.5, 0.3, 0.0]])
    tris = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    model = _model(EmitterSettings("Pancake", source="VOLUME", triangles=tris, vertex_count=4))
    ef = EmitterFrame(rate=10, verts0=verts)
    with pytest.raises(PhysanimError) as info:
        ParticleSolver(model).advance(model.state(), _inputs(5, [ef]))
    err = info.value
    assert (err.obj, err.frame, err.kind) == ("Pancake", 5, "emitter")
    message = str(err)
    assert message.startswith('emitter "Pancake" at frame 5: ')
    assert "encloses no volume (it is flat" in message and "FACES" in message
