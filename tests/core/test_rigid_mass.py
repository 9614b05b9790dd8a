"""Mass properties: exact for polyhedra (closed forms of boxes, tetrahedra, prisms, an L-shaped
solid to 1e-12 relative), converging to the closed forms of the cylinder, sphere and capsule at the
rate of the polygon's area error, invariant under rigid motions, and clear errors for open, flat
and inside-out meshes and for impossible overrides."""
from __future__ import annotations

import math

import numpy as np
import pytest

from physanim.core.collision.shapes import box_mesh, sphere_mesh
from physanim.core.errors import PhysanimError
from physanim.core.rigid.mass import (MassProperties, box_mass, capsule_mass, polyhedron_mass,
                                      sphere_mass, with_override)

EXACT = 1e-12  # relative, for polyhedra (scale-aware: errors over the largest entry)


def _rel(actual, expected, scale=None) -> float:
    """Largest error over the largest entry of ``expected`` (or over ``scale``)."""
    scale = np.abs(expected).max() if scale is None else scale
    return float(np.abs(np.asarray(actual, float) - expected).max() / scale)


def _close(actual, expected, rel=EXACT, scale=None):
    err = _rel(actual, expected, scale)
    assert err <= rel, f"relative error {err:.3g} > {rel:.3g}"


def _random_rotation(rng) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))  # det +1: a rotation, not a reflection


def _tonon(p: np.ndarray, density: float) -> np.ndarray:
    """Tonon (2004) explicit inertia tensor of a tetrahedron about its centroid, written out
    term by term over the vertex coordinates relative to the centroid."""
    q = p - p.mean(axis=0)
    k = density * abs(np.linalg.det(q[1:] - q[0]))  # density |J|, |J| = 6 volume
    x, y, z = q.T

    def square(u):  # sum over i <= j of u_i u_j
        return sum(u[i] * u[j] for i in range(4) for j in range(i, 4))

    def product(u, w):  # 2 sum u_i w_i + sum over i != j of u_i w_j
        return sum((2.0 if i == j else 1.0) * u[i] * w[j] for i in range(4) for j in range(4))

    a, b, c = (k * (square(u) + square(w)) / 60.0 for u, w in ((y, z), (x, z), (x, y)))
    a_, b_, c_ = (k * product(u, w) / 120.0 for u, w in ((y, z), (x, z), (x, y)))
    return np.array([[a, -c_, -b_], [-c_, b, -a_], [-b_, -a_, c]])


def _quadrature(p: np.ndarray, density: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Volume, centroid and inertia about it of a tetrahedron by the 4-point rule exact for
    quadratics (points at barycentric (alpha, beta, beta, beta) and permutations)."""
    alpha, beta = (5.0 + 3.0 * 5.0 ** 0.5) / 20.0, (5.0 - 5.0 ** 0.5) / 20.0
    points = (np.full((4, 4), beta) + np.eye(4) * (alpha - beta)) @ p
    volume = abs(np.linalg.det(p[1:] - p[0])) / 6.0
    centroid = points.mean(axis=0)
    r = points - centroid
    cov = density * volume / 4.0 * r.T @ r
    return volume, centroid, np.trace(cov) * np.eye(3) - cov


def _tetra_mesh(p: np.ndarray):
    tri = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    if np.linalg.det(p[1:] - p[0]) < 0:
        tri = tri[:, ::-1]
    return p, tri


def _extrude(ring: np.ndarray, half_height: float, star=(0.0, 0.0)):
    """Closed prism over a counter-clockwise polygon ``ring`` (m, 2) star-shaped about ``star``,
    z in [-half_height, half_height], caps fanned from the star point."""
    m = len(ring)
    flat = np.vstack([ring, star])
    v = np.concatenate([np.column_stack([flat, np.full(m + 1, z)])
                        for z in (-half_height, half_height)])
    i, j = np.arange(m), (np.arange(m) + 1) % m
    top = i + m + 1
    tri = np.concatenate([
        np.column_stack([np.full(m, m), j, i]),  # bottom, facing -z
        np.column_stack([np.full(m, 2 * m + 1), top, j + m + 1]),  # top, facing +z
        np.column_stack([i, j, j + m + 1]), np.column_stack([i, j + m + 1, top])])
    return v, tri


def _polygon(n: int, radius: float) -> np.ndarray:
    t = 2.0 * np.pi * np.arange(n) / n
    return radius * np.column_stack([np.cos(t), np.sin(t)])


def _capsule_mesh(radius: float, half_length: float, around: int, rings: int):
    """UV capsule along z inscribed in the exact one: ``rings`` latitude steps per cap."""
    polar = np.linspace(0.0, np.pi / 2, rings + 1)[1:]
    north = [(radius * np.sin(a), half_length + radius * np.cos(a)) for a in polar]
    profile = north + [(rho, -z) for rho, z in north[::-1]]
    t = 2.0 * np.pi * np.arange(around) / around
    ring_v = [np.column_stack([rho * np.cos(t), rho * np.sin(t), np.full(around, z)])
              for rho, z in profile]
    top = half_length + radius
    v = np.concatenate([[[0.0, 0.0, top]], *ring_v, [[0.0, 0.0, -top]]])
    i, j = np.arange(around), (np.arange(around) + 1) % around
    tris = [np.column_stack([np.zeros(around, int), 1 + i, 1 + j])]
    for k in range(len(profile) - 1):
        a, b = 1 + k * around, 1 + (k + 1) * around
        tris += [np.column_stack([a + i, b + i, b + j]), np.column_stack([a + i, b + j, a + j])]
    last, pole = 1 + (len(profile) - 1) * around, len(v) - 1
    tris.append(np.column_stack([np.full(around, pole), last + j, last + i]))
    return v, np.concatenate(tris)


def _lumpy(seed=0):
    """A non-convex, irregular closed mesh: an icosphere with random radii, off the origin."""
    rng = np.random.default_rng(seed)
    s = sphere_mesh(3)
    v = s.vertices * rng.uniform(0.6, 1.4, size=(len(s.vertices), 1)) * [1.0, 0.7, 1.9]
    return v + [0.3, -0.2, 0.5], s.triangles


# --- exact polyhedra ---------------------------------------------------------------------------


def test_box_mesh_is_exact_and_matches_box_mass():
    h = np.array([0.5, 1.25, 2.0])
    props = polyhedron_mass(box_mesh(h).vertices, box_mesh(h).triangles, density=700.0)
    m = 700.0 * 8.0 * h.prod()
    _close(props.volume, 8.0 * h.prod())
    _close(props.mass, m)
    _close(props.com, np.zeros(3), scale=h.max())
    exact = m / 3.0 * np.diag([h[1] ** 2 + h[2] ** 2, h[0] ** 2 + h[2] ** 2, h[0] ** 2 + h[1] ** 2])
    _close(props.inertia, exact)
    ref = box_mass(h, density=700.0)
    _close(ref.inertia, exact)
    _close(ref.mass, m)
    assert ref.volume == pytest.approx(props.volume, rel=EXACT)


def test_regular_tetrahedron_is_isotropic_m_a2_over_20():
    p = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float)
    edge = 2.0 * math.sqrt(2.0)
    props = polyhedron_mass(*_tetra_mesh(p), mass=3.0)
    _close(props.volume, edge ** 3 / (6.0 * math.sqrt(2.0)))
    _close(props.com, np.zeros(3), scale=edge)
    _close(props.inertia, 3.0 * edge ** 2 / 20.0 * np.eye(3))


@pytest.mark.parametrize("seed", range(5))
def test_irregular_tetrahedron_matches_tonon_and_quadrature(seed):
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(4, 3)) * [1.0, 3.0, 0.5] + rng.normal(size=3) * 2.0
    props = polyhedron_mass(*_tetra_mesh(p), density=1250.0)
    volume, centroid, inertia = _quadrature(p, 1250.0)
    _close(props.volume, volume)
    _close(props.com, centroid, scale=np.abs(p).max())
    _close(props.inertia, _tonon(p, 1250.0))
    _close(props.inertia, inertia)


def test_non_convex_l_shaped_prism_matches_three_boxes():
    ring = np.array([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], float)
    v, tri = _extrude(ring, 0.25, star=(0.5, 0.5))
    props = polyhedron_mass(v, tri, density=2.0)
    centres = np.array([[0.5, 0.5, 0.0], [1.5, 0.5, 0.0], [0.5, 1.5, 0.0]])
    com = centres.mean(axis=0)
    m = 2.0 * 0.5  # each unit square 0.5 thick
    box = box_mass((0.5, 0.5, 0.25), mass=m).inertia
    exact = sum(box + m * (d @ d * np.eye(3) - np.outer(d, d)) for d in centres - com)
    _close(props.mass, 3 * m)
    _close(props.com, com, scale=2.0)
    _close(props.inertia, exact)


def test_regular_prism_is_exact_and_converges_to_the_cylinder():
    r, hz, rho = 0.4, 0.9, 1000.0
    cylinder_mass = rho * math.pi * r * r * 2 * hz
    cylinder = cylinder_mass * np.diag([r * r / 4 + hz * hz / 3] * 2 + [r * r / 2])
    errors, area_errors = [], []
    for n in (64, 256, 1024):
        props = polyhedron_mass(*_extrude(_polygon(n, r), hz), density=rho)
        theta = 2.0 * math.pi / n
        area = 0.5 * n * r * r * math.sin(theta)
        polar = n * r ** 4 / 12.0 * math.sin(theta) * (2.0 + math.cos(theta))
        prism = rho * 2 * hz * np.diag([polar / 2 + area * hz * hz / 3] * 2 + [polar])
        _close(props.inertia, prism)  # exact for the polygon prism itself
        errors.append(abs(props.inertia[2, 2] / cylinder[2, 2] - 1.0))
        area_errors.append(1.0 - area / (math.pi * r * r))
    errors, area_errors = np.array(errors), np.array(area_errors)
    # I_zz's error is twice the area error (1 - theta^2 / 3 vs 1 - theta^2 / 6).
    assert np.allclose(errors / area_errors, 2.0, rtol=1e-2), errors / area_errors
    assert np.allclose(errors[:-1] / errors[1:], 16.0, rtol=1e-2), errors


def test_icosphere_converges_to_two_fifths_m_r2():
    r, m = 0.75, 5.0
    errors = []
    for k in range(2, 6):
        s = sphere_mesh(k, radius=r)
        props = polyhedron_mass(s.vertices, s.triangles, mass=m)
        errors.append(_rel(props.inertia, 0.4 * m * r * r * np.eye(3)))
        assert np.abs(props.com).max() < EXACT * r
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 3.5) & (ratios < 4.5)), (errors, ratios)
    assert errors[-1] < 1e-3
    ref = sphere_mass(r, mass=m)
    _close(ref.inertia, 0.4 * m * r * r * np.eye(3))
    _close(ref.volume, 4.0 / 3.0 * math.pi * r ** 3)


def test_capsule_mesh_converges_to_capsule_mass():
    r, h, rho = 0.3, 0.5, 900.0
    exact = capsule_mass(r, h, density=rho)
    errors = []
    for n in (32, 64, 128):
        props = polyhedron_mass(*_capsule_mesh(r, h, 2 * n, n // 2), density=rho)
        errors.append(max(_rel(props.inertia, exact.inertia), _rel(props.mass, exact.mass)))
        assert np.abs(props.com).max() < EXACT * (r + h)
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 3.5) & (ratios < 4.5)), (errors, ratios)
    assert errors[-1] < 1e-3
    sphere, capsule = sphere_mass(0.5, density=3.0), capsule_mass(0.5, 0.0, density=3.0)
    _close(capsule.inertia, sphere.inertia)
    _close(capsule.mass, sphere.mass)
    r, h = 0.1, 50.0
    c = capsule_mass(r, h, mass=1.0)
    assert c.inertia[0, 0] == pytest.approx((2 * h) ** 2 / 12.0, rel=0.01)
    assert c.inertia[2, 2] == pytest.approx(r * r / 2.0, rel=0.01)


# --- invariance and density -------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(4))
def test_rigid_motion_rotates_inertia_and_moves_com(seed):
    v, tri = _lumpy(seed)
    base = polyhedron_mass(v, tri, density=800.0)
    rng = np.random.default_rng(100 + seed)
    size = np.abs(v).max()
    for _ in range(5):
        rot, t = _random_rotation(rng), rng.normal(size=3) * 10.0 * size
        moved = polyhedron_mass(v @ rot.T + t, tri, density=800.0)
        _close(moved.mass, base.mass)
        _close(moved.volume, base.volume)
        _close(moved.com, rot @ base.com + t, scale=size + np.abs(t).max())
        _close(moved.inertia, rot @ base.inertia @ rot.T)


def test_density_and_mass_agree():
    v, tri = _lumpy(7)
    by_density = polyhedron_mass(v, tri, density=600.0)
    by_mass = polyhedron_mass(v, tri, mass=by_density.mass)
    _close(by_mass.inertia, by_density.inertia)
    _close(by_mass.com, by_density.com)
    assert by_mass.density == pytest.approx(600.0, rel=EXACT)
    for make in (lambda **k: sphere_mass(0.2, **k), lambda **k: box_mass((1, 2, 3), **k),
                 lambda **k: capsule_mass(0.2, 0.7, **k)):
        a = make(density=600.0)
        b = make(mass=a.mass)
        _close(b.inertia, a.inertia)
        assert b.volume == a.volume


@pytest.mark.parametrize("kwargs, match", [
    ({}, "exactly one of density"), ({"density": 1.0, "mass": 1.0}, "exactly one of density"),
    ({"mass": -2.0}, r"mass must be finite and > 0 \(got -2.0\)"),
    ({"density": float("nan")}, r"density must be finite and > 0 \(got nan\)")])
def test_density_or_mass_is_required_once(kwargs, match):
    v, tri = _lumpy()
    for call in (lambda: polyhedron_mass(v, tri, name="Rock", **kwargs),
                 lambda: box_mass((1, 1, 1), name="Rock", **kwargs)):
        with pytest.raises(ValueError, match=match) as info:
            call()
        assert 'rigid body "Rock"' in str(info.value)


def test_primitive_sizes_are_checked():
    with pytest.raises(PhysanimError, match=r'"Ball": radius must be finite and > 0 \(got 0.0\)'):
        sphere_mass(0.0, mass=1.0, name="Ball")
    with pytest.raises(PhysanimError, match=r"half_extents\[1\] must be finite and > 0"):
        box_mass((1.0, -1.0, 1.0), mass=1.0)
    with pytest.raises(PhysanimError, match=r"half_length must be finite and >= 0 \(got -1.0\)"):
        capsule_mass(1.0, -1.0, mass=1.0)


# --- overrides ------------------------------------------------------------------------------


def test_overrides_replace_com_and_inertia_and_results_are_read_only():
    props = box_mass((1, 2, 3), mass=2.0)
    for array in (props.inertia, props.com):
        with pytest.raises(ValueError, match="read-only"):
            array[0] = 5.0
    with pytest.raises(AttributeError):
        props.mass = 2.0
    moved = with_override(props, com=(0.0, 0.0, -1.0), name="Cart")
    assert moved.com.tolist() == [0.0, 0.0, -1.0]
    assert np.array_equal(moved.inertia, props.inertia)
    diag = with_override(props, inertia=(1.0, 2.0, 2.5))
    assert np.array_equal(diag.inertia, np.diag([1.0, 2.0, 2.5]))
    rot = _random_rotation(np.random.default_rng(3))
    full = with_override(props, inertia=rot @ np.diag([1.0, 2.0, 3.0]) @ rot.T)
    assert np.allclose(full.principal_moments, [1.0, 2.0, 3.0])
    assert full.mass == props.mass and full.volume == props.volume


@pytest.mark.parametrize("inertia, match", [
    ([1.0, 1.0, 3.0], "break the triangle inequality"),
    ([[2.0, 0, 0], [0, 2.0, 0], [0, 0, -1.0]], "must be positive definite"),
    ([0.0, 1.0, 1.0], "must be positive definite"),
    ([[1.0, 0.5, 0], [0, 1.0, 0], [0, 0, 1.0]], "must be symmetric"),
    ([1.0, float("inf"), 1.0], "finite 3 x 3 tensor"),
    ([[1.0, 2.0], [3.0, 4.0]], "finite 3 x 3 tensor")])
def test_impossible_inertia_overrides_are_refused(inertia, match):
    props = box_mass((1, 1, 1), mass=1.0)
    with pytest.raises(PhysanimError, match=match) as info:
        with_override(props, inertia=inertia, name="Crate")
    assert str(info.value).startswith('rigid body "Crate": ')


def test_bad_com_override_and_direct_construction_are_refused():
    props = box_mass((1, 1, 1), mass=1.0)
    with pytest.raises(PhysanimError, match=r'"Crate": centre of mass must be 3 finite numbers'):
        with_override(props, com=(0.0, float("nan"), 0.0), name="Crate")
    with pytest.raises(ValueError, match=r"mass must be finite and > 0 \(got 0.0\)"):
        MassProperties(0.0, (0, 0, 0), np.eye(3), 1.0)
    with pytest.raises(ValueError, match="volume must be finite and > 0"):
        MassProperties(1.0, (0, 0, 0), np.eye(3), -1.0)
    with pytest.raises(ValueError, match="triangle inequality"):
        MassProperties(1.0, (0, 0, 0), np.diag([1.0, 1.0, 2.5]), 1.0)
    MassProperties(1.0, (0, 0, 0), np.diag([1.0, 1.0, 2.0]), 1.0)  # a thin plate: allowed


# --- bad meshes ------------------------------------------------------------------------------

ADVICE = "Convex Hull, Box, Sphere or Capsule shape, or close the mesh"


def _raises(v, tri, match, name="Mesh"):
    with pytest.raises(PhysanimError, match=match) as info:
        polyhedron_mass(v, tri, mass=1.0, name=name)
    message = str(info.value)
    assert message.startswith(f'rigid body "{name}": '), message
    return message


def test_open_and_non_manifold_meshes_name_their_edges_and_the_shapes_that_work():
    b = box_mesh()
    msg = _raises(b.vertices, b.triangles[2:], "has 4 edges open", name="Lid")
    assert ADVICE in msg
    msg = _raises(b.vertices, b.triangles[1:], "has 3 edges open")
    assert ADVICE in msg
    fin = np.vstack([b.vertices, [[3.0, 3.0, 3.0]]])
    tri = np.vstack([b.triangles, [[0, 1, 8], [1, 0, 8]]])  # a fin on edge 0-1, closed itself
    assert ADVICE in _raises(fin, tri, "has 1 edge shared by more than two faces")


def test_flat_meshes_enclose_no_volume():
    tri = np.array([[0, 1, 2], [0, 2, 1]])  # one triangle closed on itself
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    assert ADVICE in _raises(v, tri, r"encloses no volume \(0 m\^3\)")
    flat = box_mesh((1.0, 1.0, 0.0))  # zero height: top and bottom weld together
    assert ADVICE in _raises(flat.vertices, flat.triangles, "encloses no volume")
    assert ADVICE in _raises(np.zeros((8, 3)), box_mesh().triangles, "encloses no volume")
    p = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    v, tri = _tetra_mesh(p)
    twins = np.vstack([v, v + 3.0]), np.vstack([tri, tri[:, ::-1] + 4])  # one inside out
    assert ADVICE in _raises(*twins, "encloses no volume .* its faces cancel out")


def test_inside_out_box_names_its_negative_volume():
    b = box_mesh((0.5, 0.5, 0.5))
    msg = _raises(b.vertices, b.triangles[:, ::-1], r"inside out \(volume -1 m\^3 < 0")
    assert "Recalculate Outside" in msg and ADVICE in msg


def test_partly_flipped_faces_are_refused():
    b = box_mesh()
    tri = b.triangles.copy()
    tri[:2] = tri[:2, ::-1]
    msg = _raises(b.vertices, tri, "4 edges join faces wound in opposite directions")
    assert "Recalculate Outside" in msg


def test_non_finite_vertices_and_bad_indices_are_named():
    b = box_mesh()
    v = b.vertices.copy()
    v[5, 2] = np.nan
    _raises(v, b.triangles, r"vertex 5 is not finite", name="Rock")
    _raises(b.vertices, b.triangles + 1, r"triangle \d+ refers to vertex \[\d+, \d+, 8\]")
    _raises(b.vertices, np.zeros((0, 3), int), "non-empty")


def test_split_seams_still_close():
    """Vertices duplicated at equal positions (unwelded imports) count as one for closure."""
    b = box_mesh((1.0, 2.0, 3.0))
    v = b.vertices[b.triangles].reshape(-1, 3)  # every triangle with its own three vertices
    tri = np.arange(len(v)).reshape(-1, 3)
    _close(polyhedron_mass(v, tri, mass=1.0).inertia, box_mass((1, 2, 3), mass=1.0).inertia)
