"""A collider collides with what the user sees: a mesh that is exactly a box or a filled
rectangle becomes that analytic shape through a fitted matrix, any other mesh stays a mesh; the
analytic shape then gives the same collisions as the mesh itself."""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.collision.shapes import box_mesh, grid_mesh, sphere_mesh
from physanim.core.contact import ColliderFrame
from physanim.core.particles import EmitterFrame, EmitterSettings, FrameInputs, ParticleSolver
from physanim.core.contact.fit import fit_analytic_shape
from physanim.tests.core.helpers import particle_model, place, rotation, translation

DT = 1.0 / 24.0


def _corners(fit: np.ndarray, z: float = 1.0) -> np.ndarray:
    pts = np.array([[x, y, zz, 1.0] for x in (-1, 1) for y in (-1, 1) for zz in (-z, z)])
    return (pts @ fit.T)[:, :3]


def _loop_cut_box(half, cuts: int = 3):
    """A box whose sides are subdivided grids (vertices on edges and faces, not only corners)."""
    verts, tris = [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            g = grid_mesh(cuts + 2, 2.0)
            local = g.vertices - [1.0, 1.0, 0.0]
            u, v = [k for k in range(3) if k != axis]
            p = np.zeros_like(local)
            p[:, u], p[:, v], p[:, axis] = local[:, 0] * half[u], local[:, 1] * half[v], sign * half[axis]
            tris.append(g.triangles + sum(len(x) for x in verts))
            verts.append(p)
    return np.concatenate(verts), np.concatenate(tris)


def test_a_box_mesh_is_a_box_and_its_fit_maps_the_unit_cube_onto_it():
    half = np.array([0.5, 2.0, 1.5])
    mesh = box_mesh(tuple(half))
    verts = mesh.vertices + [3.0, -1.0, 0.25]
    shape, fit = fit_analytic_shape(verts, mesh.triangles)
    assert shape == "BOX"
    got = {tuple(np.round(c, 9)) for c in _corners(fit)}
    want = {tuple(np.round(c, 9)) for c in np.unique(verts, axis=0)}
    assert got == want
    # loop cuts do not make it less of a box
    v2, t2 = _loop_cut_box(half)
    assert fit_analytic_shape(v2, t2)[0] == "BOX"


@pytest.mark.parametrize("plane_axes", [(0, 1, 2), (0, 2, 1), (1, 2, 0)])
def test_a_filled_rectangle_is_a_plane_in_any_axis_plane(plane_axes):
    u, v, normal = plane_axes
    g = grid_mesh(13, 2.0)  # 12 x 12 quads in z = 0, [0, 2]^2
    verts = np.zeros_like(g.vertices)
    verts[:, u] = g.vertices[:, 0] * 1.5 - 0.5
    verts[:, v] = g.vertices[:, 1] * 0.25
    verts[:, normal] = 0.7
    shape, fit = fit_analytic_shape(verts, g.triangles)
    assert shape == "PLANE"
    assert np.linalg.det(fit[:3, :3]) > 0.0  # a proper rotation and scale: never mirrored
    corners = {tuple(np.round(c, 9)) for c in _corners(fit, 0.0)}
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    want = set()
    for a in (lo[u], hi[u]):
        for b in (lo[v], hi[v]):
            c = np.zeros(3)
            c[u], c[v], c[normal] = a, b, 0.7
            want.add(tuple(np.round(c, 9)))
    assert corners == want


def test_other_meshes_stay_meshes():
    sphere = sphere_mesh(2)
    assert fit_analytic_shape(sphere.vertices, sphere.triangles)[0] == "MESH"
    box = box_mesh((1.0, 1.0, 1.0))
    open_box = box.triangles[:-2]  # one side missing
    assert fit_analytic_shape(box.vertices, open_box)[0] == "MESH"
    g = grid_mesh(5, 2.0)
    l_shape = g.triangles[: len(g.triangles) * 3 // 4]  # a flat sheet that is not a rectangle
    assert fit_analytic_shape(g.vertices, l_shape)[0] == "MESH"
    bumpy = grid_mesh(9, 2.0, amplitude=0.05)
    assert fit_analytic_shape(bumpy.vertices, bumpy.triangles)[0] == "MESH"
    inner = np.concatenate([box.triangles, [[0, 7, 3]]])  # an extra face through the inside
    assert fit_analytic_shape(box.vertices, inner)[0] == "MESH"
    assert fit_analytic_shape(np.zeros((3, 3)), np.array([[0, 1, 2]]))[0] == "MESH"


def _shoot(collider: ColliderFrame, x0, v0, frames: int = 36):
    model = particle_model(EmitterSettings("Shot"))
    state = model.state()
    place(state, x0, v0)
    solver = ParticleSolver(model, "SYMPLECTIC_EULER", substeps=2)
    for f in range(frames):
        solver.advance(state, FrameInputs(frame=f, t0=f * DT, frame_dt=DT,
                                          emitters=[EmitterFrame(active=False)],
                                          colliders=[collider]))
    return state.particle_x


@pytest.mark.parametrize("kind", ["box", "plane"])
def test_fitted_shape_collides_like_the_mesh_it_replaces(kind):
    rng = np.random.default_rng(3)
    if kind == "box":
        mesh = box_mesh((0.6, 1.1, 0.4))
        verts, tris = mesh.vertices + [0.2, 0.0, 0.3], mesh.triangles
    else:
        g = grid_mesh(13, 3.0)
        verts, tris = g.vertices - [1.5, 1.0, 0.0], g.triangles
    shape, fit = fit_analytic_shape(verts, tris)
    assert shape == kind.upper()
    world = translation(0.0, 0.0, -1.0) @ rotation((1.0, 0.3, 0.2), 0.5)
    n = 60
    x0 = np.column_stack([rng.uniform(-0.8, 0.8, n), rng.uniform(-0.8, 0.8, n),
                          rng.uniform(1.5, 3.0, n)])
    v0 = rng.normal(size=(n, 3)) * [1.0, 1.0, 3.0] - [0.0, 0.0, 6.0]
    kw = dict(restitution=0.5, friction=0.3)
    mesh_x = _shoot(ColliderFrame("C", "MESH", world, world, vertices0=verts, vertices1=verts,
                                  triangles=tris, **kw), x0, v0)
    fit_x = _shoot(ColliderFrame("C", shape, world @ fit, world @ fit, **kw), x0, v0)
    # the same surface: the same bounces, slides and rests (time-of-impact rounding apart)
    np.testing.assert_allclose(fit_x, mesh_x, atol=1e-5)
