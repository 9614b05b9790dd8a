"""Bad input: clear errors naming the value, or documented behaviour — never a crash or a silent
miss. Degenerate and zero-area triangles, non-manifold and open meshes, duplicate vertices, NaN
positions, singular transforms and empty queries."""
from __future__ import annotations


import numpy as np
import pytest

from physanim.core.collision import (KINDS, TriangleMesh, build_bvh, closest_points, collide,
                                     convex_hull, ray_hits, segment_hits, triangles_overlap)
from physanim.core.collision.shapes import grid_mesh, sphere_mesh
from physanim.core.errors import PhysanimError


def _brute(a, b):
    ta, tb = a.triangle_vertices, b.triangle_vertices
    i, j = (x.ravel() for x in np.meshgrid(np.arange(len(ta)), np.arange(len(tb)),
                                           indexing="ij"))
    ok = triangles_overlap(ta[i], tb[j])
    return np.stack([i[ok], j[ok]], axis=1)


def test_non_finite_vertices_are_named():
    v = np.zeros((5, 3))
    v[3, 1] = np.nan
    with pytest.raises(PhysanimError, match=r'mesh "Ground": vertex 3 is not finite: '
                                            r'\[0.0, nan, 0.0\]'):
        TriangleMesh(v, [[0, 1, 2]], "Ground")
    good = grid_mesh(3, name="Ground")
    v = good.vertices.copy()
    v[4] = np.inf
    with pytest.raises(PhysanimError, match="vertex 4 is not finite"):
        good.with_vertices(v)
    with pytest.raises(PhysanimError, match="vertex 4 is not finite"):
        build_bvh(good, "aabb").refit(v)


def test_bad_triangles_are_named():
    v = np.eye(3)
    with pytest.raises(PhysanimError, match=r"triangle 1 refers to vertex \[0, 1, 3\]"):
        TriangleMesh(v, [[0, 1, 2], [0, 1, 3]])
    with pytest.raises(PhysanimError, match="refers to vertex"):
        TriangleMesh(v, [[0, 1, -1]])
    with pytest.raises(PhysanimError, match="must be integers"):
        TriangleMesh(v, [[0, 1, 1.5]])
    with pytest.raises(PhysanimError, match=r"\(n, 3\) array"):
        TriangleMesh(v, [[0, 1]])
    with pytest.raises(PhysanimError, match="no triangles"):
        TriangleMesh(v, np.zeros((0, 3), dtype=int))
    with pytest.raises(PhysanimError, match=r"\(n, 3\) array"):
        TriangleMesh(np.zeros((3, 2)), [[0, 1, 2]])
    with pytest.raises(PhysanimError, match="keep the shape"):
        TriangleMesh(v, [[0, 1, 2]]).with_vertices(np.zeros((4, 3)))


def test_bad_queries_are_named():
    bvh = build_bvh(sphere_mesh(1, name="Ball"), "obb")
    p = np.zeros((4, 3))
    p[2, 0] = np.nan
    with pytest.raises(PhysanimError, match=r'mesh "Ball": query point 2 is not finite'):
        closest_points(bvh, p)
    with pytest.raises(PhysanimError, match="segment end 2 is not finite"):
        segment_hits(bvh, np.zeros((4, 3)), p)
    with pytest.raises(PhysanimError, match="ray direction 2 is not finite"):
        ray_hits(bvh, np.zeros((4, 3)), p)
    with pytest.raises(PhysanimError, match="singular"):
        segment_hits(bvh, np.zeros((1, 3)), np.ones((1, 3)), matrix=np.diag([1, 0, 1, 1.0]))
    with pytest.raises(ValueError, match="max_distance"):
        closest_points(bvh, np.zeros((1, 3)), max_distance=0.0)
    with pytest.raises(ValueError, match="differ in shape"):
        segment_hits(bvh, np.zeros((2, 3)), np.zeros((3, 3)))


def test_empty_queries_return_empty_results():
    bvh = build_bvh(sphere_mesh(1), "aabb")
    none = np.zeros((0, 3))
    assert segment_hits(bvh, none, none).hit.shape == (0,)
    assert ray_hits(bvh, none, none).t.shape == (0,)
    assert closest_points(bvh, none).distance.shape == (0,)


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_zero_area_mesh_is_a_set_of_segments(kind):
    # every triangle collinear: overlap tests treat them exactly as segments; segments and
    # rays pass through (no area); distances are to the segments, with no inside
    t = np.arange(12) / 8.0 - 0.75  # exactly collinear in binary
    v = np.c_[t, 0.5 * t, np.zeros(12)]
    line = TriangleMesh(v, np.stack([np.arange(10), np.arange(1, 11), np.arange(2, 12)], 1),
                        "Wire")
    assert line.degenerate.all()
    bvh = build_bvh(line, kind)
    bvh.check()
    plate = grid_mesh(5, size=2.0)
    plate = TriangleMesh(plate.vertices - [1.0, 1.0, 0.0], plate.triangles)
    plate_tree = build_bvh(plate, kind)
    got = collide(bvh, plate_tree)
    want = _brute(line, plate)
    assert len(want) > 0  # the wire lies in the plate: coplanar segment contacts
    np.testing.assert_array_equal(got.pairs, want)
    assert not segment_hits(bvh, [[0, 0, 1.0]], [[0, 0, -1.0]]).hit.any()
    d = closest_points(bvh, [[0.0, 0.0, 0.5], [0.5, 0.25, 0.0]])
    np.testing.assert_allclose(d.distance, [0.5, 0.0], atol=1e-15)
    assert np.all(d.signed_distance >= 0)


def test_degenerate_duplicate_and_non_manifold_meshes():
    # a fan of three triangles on one edge (non-manifold), a zero-area sliver, a duplicated
    # vertex and a repeated triangle: everything builds and queries agree with brute force
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0.2], [0.5, 0, 1],
                  [0.5, 0, 0], [0, 0, 0]], dtype=float)
    tri = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4], [0, 5, 1], [6, 1, 2], [0, 1, 2]])
    odd = TriangleMesh(v, tri, "Odd")
    np.testing.assert_array_equal(odd.degenerate, [False, False, False, True, False, False])
    assert odd.welded[6] == odd.welded[0]
    other = sphere_mesh(1, radius=0.4)
    other = TriangleMesh(other.vertices + [0.5, 0.2, 0.1], other.triangles)
    for kind in ("aabb", "obb", "sphere", "kdop18"):
        got = collide(build_bvh(odd, kind, leaf_size=1), build_bvh(other, kind))
        np.testing.assert_array_equal(got.pairs, _brute(odd, other))
    bvh = build_bvh(odd, "obb")
    hits = segment_hits(bvh, [[0.5, 0.2, 1.0], [0.5, 0.0, 1.0]], [[0.5, 0.2, -1.0],
                                                                [0.5, 0.0, -1.0]])
    assert hits.hit.all()
    assert hits.triangle[1] != 3  # the sliver along the edge is never the one hit
    d = closest_points(bvh, [[0.5, 0.3, 0.5], [0.5, 0.0, -0.5]])
    assert np.all(np.isfinite(d.signed_distance))


def test_tiny_meshes_build_with_every_builder_and_kind():
    one = TriangleMesh(np.eye(3), [[0, 1, 2]])
    twice = TriangleMesh(np.eye(3), [[0, 1, 2], [0, 2, 1]])  # the same triangle, both windings
    for mesh in (one, twice):
        for method in ("topdown", "bottomup", "incremental"):
            for kind in KINDS:
                bvh = build_bvh(mesh, kind, method, arity=4, leaf_size=1)
                bvh.check()
                n = mesh.triangle_count
                assert len(collide(bvh, bvh).pairs) == n * n
                assert segment_hits(bvh, [[0.2, 0.3, 1.0]], [[0.2, 0.3, -1.0]]).hit.all()


def test_convex_hull_degenerate_inputs():
    rng = np.random.default_rng(0)
    assert convex_hull(np.ones((4, 3))).dimension == 0
    assert convex_hull(np.outer(rng.normal(size=9), [1, 2, 3])).dimension == 1
    flat = convex_hull(np.c_[rng.normal(size=(30, 2)), np.zeros(30)])
    assert flat.dimension == 2 and flat.volume == 0.0 and flat.area > 0
    with pytest.raises(ValueError, match="no points"):
        convex_hull(np.zeros((0, 3)))
    with pytest.raises(PhysanimError, match="point 1 is not finite"):
        convex_hull([[0, 0, 0], [np.nan, 0, 0]])
