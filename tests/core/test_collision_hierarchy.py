"""Hierarchy building and refitting: layout invariants, volumes that hold their triangles, split
rules and their fallbacks, and refits that update exactly the volumes over moved triangles."""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.collision import (TriangleMesh, build_bottomup, build_bvh,
                                     build_incremental, build_topdown, bounding_volume)
from physanim.core.collision.build_bottomup import morton_order
from physanim.core.collision.shapes import grid_mesh, sphere_mesh

KINDS = ["sphere", "aabb", "obb", "obb_hull", "obb_triangles", "obb6", "kdop14", "kdop18",
         "kdop26"]
BUILDS = [("topdown", {"split": "center"}), ("topdown", {"split": "median"}),
          ("bottomup", {}), ("incremental", {})]


def _contains_triangles(bvh) -> bool:
    """Every node's volume holds every vertex of every triangle under it."""
    node = np.repeat(np.arange(bvh.node_count), bvh.node_tri_count)
    pos = np.concatenate([np.arange(f, f + c) for f, c in zip(bvh.node_first,
                                                              bvh.node_tri_count)])
    tri = bvh.ordered_triangles[pos]
    ok = np.ones(len(node), dtype=bool)
    for k in range(3):
        ok &= bvh.kind.contains(bvh.node_bv[node], tri[:, k], margin=1e-9)
    return bool(ok.all())


@pytest.fixture(scope="module")
def bumpy():
    mesh = sphere_mesh(2)
    rng = np.random.default_rng(0)
    v = mesh.vertices * rng.uniform(0.8, 1.2, (mesh.vertex_count, 1))
    return TriangleMesh(v, mesh.triangles, "bumpy")


@pytest.mark.parametrize("method,options", BUILDS, ids=lambda x: str(x))
@pytest.mark.parametrize("kind", KINDS)
def test_every_builder_and_kind_lays_out_a_valid_tree(bumpy, method, options, kind):
    # (the hull fit runs a quickhull per node: one shape is enough for it)
    for arity, leaf in ((2, 1), (4, 3))[kind == "obb_hull":]:
        bvh = build_bvh(bumpy, kind, method, arity=arity, leaf_size=leaf, **options)
        bvh.check()
        assert bvh.arity == arity and bvh.leaf_size == leaf
        assert _contains_triangles(bvh)
        assert bvh.node_bv.shape == (bvh.node_count, bounding_volume(kind).width)
        assert not bvh.node_bv.flags.writeable
        if arity == 4:  # collapsing really makes wide nodes
            assert (bvh.node_child >= 0).sum(axis=1).max() == 4


def test_median_split_is_balanced_and_center_split_follows_geometry():
    mesh = grid_mesh(33)  # 2048 triangles
    median = build_topdown(mesh, "aabb", split="median", leaf_size=4)
    assert median.depth == 9  # 2048 / 2^9 = 4 per leaf
    assert np.all(median.node_tri_count[median.node_is_leaf] == 4)
    center = build_topdown(mesh, "aabb", split="center", leaf_size=4)
    center.check()
    # the root's children split the square along x or y at its centre
    kids = center.node_child[0]
    c = [center.ordered_triangles[center.node_first[k]:center.node_first[k]
                                  + center.node_tri_count[k]].mean(axis=1) for k in kids]
    axis = int(np.argmax(np.abs(c[0].mean(0) - c[1].mean(0))))
    assert c[0][:, axis].max() < 0.5 <= c[1][:, axis].min()


def test_failed_splits_fall_back_to_other_axes_then_halving():
    # long thin triangles whose centroids all share x (the longest extent): the x split fails
    n = 64
    y = np.arange(n, dtype=float) * 0.01
    v = np.concatenate([np.stack([np.full(n, -10.0), y, np.zeros(n)], 1),
                        np.stack([np.full(n, 10.0), y, np.zeros(n)], 1),
                        np.stack([np.zeros(n), y + 0.005, np.full(n, 0.001)], 1)])
    tri = np.stack([np.arange(n), np.arange(n) + n, np.arange(n) + 2 * n], 1)
    for split in ("center", "median"):
        bvh = build_topdown(TriangleMesh(v, tri), "aabb", split=split, leaf_size=2)
        bvh.check()
        assert bvh.depth <= 6  # split along y, not a degenerate chain
    # identical triangles: every axis fails, the triangles are halved in order
    same = TriangleMesh(np.eye(3), np.zeros((50, 3), dtype=int) + [0, 1, 2])
    for kind in ("aabb", "obb", "sphere"):
        bvh = build_topdown(same, kind, leaf_size=4)
        bvh.check()
        assert bvh.node_tri_count[bvh.node_is_leaf].max() <= 4


def test_bottomup_and_incremental_group_nearby_triangles():
    # on a grid, good trees keep leaves compact: compare total leaf volume to top-down's
    mesh = grid_mesh(17, amplitude=0.1)

    def measure(b):
        return b.kind.measure(b.node_bv[b.node_is_leaf], 1e-3).sum()

    top = measure(build_topdown(mesh, "aabb"))
    assert measure(build_bottomup(mesh, "aabb")) < 2.0 * top
    assert measure(build_incremental(mesh, "aabb")) < 3.0 * top
    # the insertion order matters but any order gives a valid tree
    a = build_incremental(mesh, "aabb", seed=1)
    b = build_incremental(mesh, "aabb", order=np.arange(mesh.triangle_count))
    a.check()
    b.check()


def test_morton_order_keeps_neighbours_close():
    rng = np.random.default_rng(1)
    p = rng.uniform(0, 1, (4096, 3))
    o = morton_order(p)
    step = np.linalg.norm(np.diff(p[o], axis=0), axis=1).mean()
    assert step < 0.25 * np.linalg.norm(np.diff(p, axis=0), axis=1).mean()


@pytest.mark.parametrize("kind", ["sphere", "aabb", "obb", "kdop26"])
def test_refit_updates_exactly_the_volumes_over_moved_triangles(kind):
    mesh = grid_mesh(21, amplitude=0.05)
    bvh = build_topdown(mesh, kind, arity=4)
    same, n_u = bvh.refit(mesh.vertices.copy())
    assert n_u == 0 and np.array_equal(same.node_bv, bvh.node_bv)
    v = mesh.vertices.copy()
    moved = np.nonzero(v[:, 0] > 0.7)[0]
    v[moved, 2] += 0.3 * np.sin(7 * v[moved, 1])
    new, n_u = bvh.refit(v)
    new.check()
    assert _contains_triangles(new)
    moved_t = np.isin(mesh.triangles, moved).any(axis=1)
    touched = np.array([moved_t[bvh.tri_order[f:f + c]].any()
                        for f, c in zip(bvh.node_first, bvh.node_tri_count)])
    assert n_u == touched.sum() and 0 < n_u < bvh.node_count
    assert np.array_equal(new.node_bv[~touched], bvh.node_bv[~touched])
    if kind == "obb":  # refitted boxes keep their axes
        np.testing.assert_array_equal(new.node_bv[:, 3:12], bvh.node_bv[:, 3:12])
    # one moved vertex: only the nodes on the paths to its triangles
    v2 = mesh.vertices.copy()
    v2[200] += 0.01
    _, n_u = bvh.refit(v2)
    assert 1 <= n_u <= 6 * (bvh.depth + 1)


def test_builder_options_are_validated(bumpy):
    with pytest.raises(ValueError, match="arity"):
        build_topdown(bumpy, "aabb", arity=1)
    with pytest.raises(ValueError, match="leaf_size"):
        build_bottomup(bumpy, "aabb", leaf_size=0)
    with pytest.raises(ValueError, match="split"):
        build_topdown(bumpy, "aabb", split="sah")
    with pytest.raises(ValueError, match="permutation"):
        build_incremental(bumpy, "aabb", order=np.zeros(bumpy.triangle_count, dtype=int))
    with pytest.raises(ValueError, match="unknown hierarchy builder"):
        build_bvh(bumpy, "aabb", "octree")
