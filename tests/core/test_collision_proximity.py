"""Segments, rays and points against a mesh: first hits and closest points equal brute force over
all triangles (10,000+ queries each), the exact segment-triangle test agrees with an independent
floating-point reference, segments through shared edges and vertices never slip through, and
signed distances agree with an independent winding-number reference."""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.collision import (TriangleMesh, build_bvh, closest_points, ray_hits,
                                     segment_hits)
from physanim.core.collision.distance import closest_on_triangles
from physanim.core.collision.raycast import segment_triangle
from physanim.core.collision.shapes import box_mesh, grid_mesh, sphere_mesh
from physanim.core.transforms import compose, transform_points

KINDS = ["sphere", "aabb", "obb", "obb6", "kdop18", "kdop26"]
N = 10_000


@pytest.fixture(scope="module")
def bumpy():
    mesh = sphere_mesh(2)
    rng = np.random.default_rng(0)
    return TriangleMesh(mesh.vertices * rng.uniform(0.8, 1.2, (mesh.vertex_count, 1)),
                        mesh.triangles, "bumpy")


@pytest.fixture(scope="module")
def segments():
    rng = np.random.default_rng(1)
    p0 = rng.normal(size=(N, 3)) * 1.3
    p1 = p0 + rng.normal(size=(N, 3)) * rng.uniform(0.2, 3.0, (N, 1))
    return p0, p1


def _brute_first_hits(mesh, p0, p1):
    """Earliest hit of each segment over all triangles (ties: lowest id), after a box filter."""
    tri = mesh.triangle_vertices
    lo, hi = np.minimum(p0, p1), np.maximum(p0, p1)
    s, t = np.nonzero(np.all(lo[:, None] <= tri.max(axis=1)[None], axis=2)
                      & np.all(hi[:, None] >= tri.min(axis=1)[None], axis=2))
    hit, tt = segment_triangle(p0[s], p1[s], tri[t])
    hit &= ~mesh.degenerate[t]
    best_t = np.full(len(p0), np.inf)
    best = np.full(len(p0), -1)
    s, t, tt = s[hit], t[hit], tt[hit]
    o = np.lexsort((t, tt, s))[::-1]  # last write wins: the earliest, lowest id
    best_t[s[o]] = tt[o]
    best[s[o]] = t[o]
    return best_t, best


@pytest.fixture(scope="module")
def brute_hits(bumpy, segments):
    return _brute_first_hits(bumpy, *segments)


@pytest.mark.parametrize("kind", KINDS)
def test_segment_first_hit_equals_brute_force(bumpy, segments, brute_hits, kind):
    p0, p1 = segments
    for arity in (2, 4):
        got = segment_hits(build_bvh(bumpy, kind, arity=arity), p0, p1)
        want_t, want_tri = brute_hits
        np.testing.assert_array_equal(got.triangle, want_tri)
        np.testing.assert_array_equal(got.t, want_t)
        assert 0.15 < got.hit.mean() < 0.85
        np.testing.assert_allclose(got.point[got.hit],
                                   p0[got.hit] + got.t[got.hit, None] * (p1 - p0)[got.hit])
        # the normal faces the segment's start; front says whether that is the winding side
        d = (p1 - p0)[got.hit]
        assert np.all(np.einsum("ij,ij->i", got.normal[got.hit], d) <= 0)
        np.testing.assert_allclose(np.linalg.norm(got.normal[got.hit], axis=1), 1.0)
        assert 0 < got.front[got.hit].mean() < 1
        assert got.n_p < 0.1 * N * bumpy.triangle_count and got.n_v > 0 and got.n_u == 0


def test_segment_triangle_matches_floating_point_reference():
    # Moller-Trumbore in floating point, away from edges and from the plane (1e-9 margins)
    rng = np.random.default_rng(2)
    n = 30_000
    tri = rng.normal(size=(n, 3, 3))
    p0 = rng.normal(size=(n, 3)) * 1.5
    p1 = rng.normal(size=(n, 3)) * 1.5
    hit, t = segment_triangle(p0, p1, tri)
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    d = p1 - p0
    h = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, h)
    s = p0 - tri[:, 0]
    u = np.einsum("ij,ij->i", s, h) / det
    q = np.cross(s, e1)
    v = np.einsum("ij,ij->i", d, q) / det
    tt = np.einsum("ij,ij->i", e2, q) / det
    want = (u >= 0) & (v >= 0) & (u + v <= 1) & (tt >= 0) & (tt <= 1)
    sure = np.min(np.abs(np.stack([u, v, 1 - u - v, tt, 1 - tt])), axis=0) > 1e-9
    np.testing.assert_array_equal(hit[sure], want[sure])
    np.testing.assert_allclose(t[sure & want], tt[sure & want], atol=1e-9)
    assert sure.sum() > 25_000 and 0.05 < want.mean() < 0.5


def test_segments_through_shared_edges_and_vertices_never_slip_through(bumpy):
    # aim at points on edges and at vertices of a rotated closed mesh, from outside to inside
    rng = np.random.default_rng(3)
    m = compose([0.3, -0.2, 0.1], [0.8, 0.3, -0.2, 0.4], np.ones(3))
    mesh = TriangleMesh(transform_points(m, bumpy.vertices), bumpy.triangles)
    tri = mesh.triangle_vertices
    k = rng.integers(0, len(tri), N)
    w = rng.uniform(0, 1, N)
    w[: N // 4] = 0.0  # exactly at a vertex
    target = tri[k, 0] + w[:, None] * (tri[k, 1] - tri[k, 0])
    centre = mesh.vertices.mean(axis=0)
    outside = centre + 3.0 * (target - centre)
    inside = centre + 0.2 * (target - centre)
    for kind in ("aabb", "obb"):
        bvh = build_bvh(mesh, kind)
        assert segment_hits(bvh, outside, inside).hit.all()
        assert segment_hits(bvh, inside, outside).hit.all()
    # and on an exactly representable grid: through vertices and edge midpoints, exactly
    grid = build_bvh(grid_mesh(9), "aabb")
    xy = np.stack(np.meshgrid(np.arange(17) / 16, np.arange(17) / 16), -1).reshape(-1, 2)
    top = np.c_[xy, np.full(len(xy), 0.5)]
    got = segment_hits(grid, top, top - [0, 0, 1.0])
    assert got.hit.all()
    np.testing.assert_array_equal(got.t, 0.5)


def test_segment_conventions():
    mesh = TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 2, 2], [3, 3, 3], [4, 4, 4]],
                        [[0, 1, 2], [3, 4, 5]])
    bvh = build_bvh(mesh, "aabb")
    p0 = np.array([[0.2, 0.2, 0.0], [0.2, 0.2, -1.0], [-1, 0.2, 0.0], [2.5, 2.5, 2.0],
                   [0.2, 0.2, 1.0]])
    p1 = np.array([[0.2, 0.2, 1.0], [0.2, 0.2, 1.0], [2, 0.2, 0.0], [2.5, 2.5, 4.0],
                   [0.2, 0.2, 1.5]])
    got = segment_hits(bvh, p0, p1)
    # starting on the surface hits at t = 0; crossing from below hits the back (front False);
    # moving within the plane grazes; zero-area triangles are never hit; short of the surface
    np.testing.assert_array_equal(got.hit, [True, True, False, False, False])
    np.testing.assert_array_equal(got.t[:2], [0.0, 0.5])
    np.testing.assert_array_equal(got.front[:2], [False, False])
    np.testing.assert_array_equal(got.normal[1], [0, 0, -1.0])
    down = segment_hits(bvh, [[0.2, 0.2, 1.0]], [[0.2, 0.2, -1.0]])
    assert down.front[0] and np.array_equal(down.normal[0], [0, 0, 1.0])


def test_rays_and_transforms(bumpy):
    bvh = build_bvh(bumpy, "obb")
    rng = np.random.default_rng(4)
    d = rng.normal(size=(2000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    origin = -5.0 * d
    got = ray_hits(bvh, origin, d)
    assert got.hit.all()
    r = np.linalg.norm(got.point, axis=1)
    assert np.all((r > 0.79) & (r < 1.21))
    np.testing.assert_allclose(got.t, np.linalg.norm(got.point - origin, axis=1), rtol=1e-12)
    assert not ray_hits(bvh, origin, d, max_t=3.5).hit.any()
    assert not ray_hits(bvh, origin, -d).hit.any()
    # a transformed mesh: world-space queries equal local queries mapped
    m = compose([1, 2, 3], [0.9, 0.1, -0.3, 0.2], [2.0, 2.0, 2.0])
    p0, p1 = origin[:500], origin[:500] + 6 * d[:500]
    world = segment_hits(bvh, transform_points(m, p0), transform_points(m, p1), matrix=m)
    local = segment_hits(bvh, p0, p1)
    np.testing.assert_array_equal(world.triangle, local.triangle)
    np.testing.assert_allclose(world.t, local.t, atol=1e-12)
    np.testing.assert_allclose(world.point, transform_points(m, local.point), atol=1e-9)
    np.testing.assert_allclose(world.normal, local.normal @ m[:3, :3].T / 2.0, atol=1e-9)


# --- closest points and signed distance --------------------------------------------------------

@pytest.fixture(scope="module")
def queries():
    rng = np.random.default_rng(5)
    return rng.normal(size=(N, 3)) * 0.9


@pytest.fixture(scope="module")
def brute_closest(bumpy, queries):
    tri = bumpy.triangle_vertices
    best = np.empty(len(queries))
    for s in range(0, len(queries), 1000):
        q = queries[s:s + 1000]
        _, d2, _ = closest_on_triangles(np.repeat(q, len(tri), 0), np.tile(tri, (len(q), 1, 1)))
        best[s:s + 1000] = np.sqrt(d2.reshape(len(q), -1).min(axis=1))
    return best


def _winding_number(points, tri):
    """Generalised winding number: total solid angle of the triangles / 4 pi (independent)."""
    out = np.empty(len(points))
    for s in range(0, len(points), 500):
        p = points[s:s + 500, None, None, :]
        a, b, c = (tri[None, :, k] - p[:, :, 0] for k in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        num = np.einsum("nmi,nmi->nm", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("nmi,nmi->nm", a, b) * lc
               + np.einsum("nmi,nmi->nm", b, c) * la + np.einsum("nmi,nmi->nm", c, a) * lb)
        out[s:s + 500] = (2 * np.arctan2(num, den)).sum(axis=1) / (4 * np.pi)
    return out


@pytest.mark.parametrize("kind", KINDS)
def test_closest_points_equal_brute_force(bumpy, queries, brute_closest, kind):
    got = closest_points(build_bvh(bumpy, kind, "bottomup", arity=4), queries)
    np.testing.assert_allclose(got.distance, brute_closest, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(got.point - queries, axis=1), got.distance,
                               rtol=1e-9, atol=1e-12)
    # the point lies on the reported triangle
    _, d2, _ = closest_on_triangles(got.point, bumpy.triangle_vertices[got.triangle])
    assert np.sqrt(d2).max() < 1e-9
    assert got.n_u == 0 and got.n_p < 0.2 * N * bumpy.triangle_count


def test_signed_distance_matches_winding_number_on_a_closed_mesh(bumpy, queries):
    got = closest_points(build_bvh(bumpy, "obb"), queries)
    inside = _winding_number(queries, bumpy.triangle_vertices) > 0.5
    sure = got.distance > 1e-9
    np.testing.assert_array_equal((got.signed_distance < 0)[sure], inside[sure])
    assert 0.2 < inside.mean() < 0.8
    np.testing.assert_allclose(np.abs(got.signed_distance), got.distance)
    np.testing.assert_allclose(np.linalg.norm(got.normal, axis=1), 1.0)


def test_signed_distance_on_open_meshes_and_unwelded_vertices():
    # open grid, winding normal +z: the sign is the side of the nearest surface
    grid = build_bvh(grid_mesh(11), "aabb")
    rng = np.random.default_rng(6)
    p = np.c_[rng.uniform(0.1, 0.9, (2000, 2)), rng.uniform(-1, 1, 2000)]
    got = closest_points(grid, p)
    np.testing.assert_allclose(got.signed_distance, p[:, 2], atol=1e-12)
    # a box with every triangle on its own three vertices (split normals, UV seams) gives the
    # same signed distances as the welded box: coincident vertices are welded for the sign
    welded = box_mesh((1.0, 0.5, 0.25))
    split = TriangleMesh(welded.triangle_vertices.reshape(-1, 3),
                         np.arange(3 * welded.triangle_count).reshape(-1, 3))
    q = rng.normal(size=(5000, 3))
    a = closest_points(build_bvh(welded, "obb"), q).signed_distance
    b = closest_points(build_bvh(split, "obb"), q).signed_distance
    np.testing.assert_allclose(a, b, atol=1e-12)
    inside = np.all(np.abs(q) < [1.0, 0.5, 0.25], axis=1)
    np.testing.assert_array_equal(a < 0, inside)


def test_max_distance_and_world_transform(bumpy, queries):
    bvh = build_bvh(bumpy, "aabb")
    full = closest_points(bvh, queries)
    near = closest_points(bvh, queries, max_distance=0.1)
    close = full.distance <= 0.1
    np.testing.assert_array_equal(near.triangle >= 0, close)
    np.testing.assert_allclose(near.distance[close], full.distance[close])
    assert np.isinf(near.distance[~close]).all() and near.n_v < full.n_v
    m = compose([1, -2, 0.5], [0.3, 0.5, 0.1, -0.7], [1.5, 1.5, 1.5])
    world = closest_points(bvh, transform_points(m, queries[:1000]), matrix=m)
    np.testing.assert_allclose(world.signed_distance, 1.5 * full.signed_distance[:1000],
                               rtol=1e-9)
    np.testing.assert_allclose(world.point, transform_points(m, full.point[:1000]), atol=1e-9)
    mirror = compose([0.5, 0, 0], [1, 0, 0, 0], [-2.0, 2.0, 2.0])
    q = transform_points(mirror, queries[:1000])
    world = closest_points(bvh, q, matrix=mirror)
    np.testing.assert_allclose(world.signed_distance, 2.0 * full.signed_distance[:1000],
                               rtol=1e-9)
    side = np.einsum("ij,ij->i", q - world.point, world.normal)
    far = world.distance > 1e-9
    np.testing.assert_array_equal(np.sign(side[far]), np.sign(world.signed_distance[far]))
