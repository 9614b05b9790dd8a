"""Mesh against mesh: determination returns exactly the brute-force triangle pairs for every
builder, bounding-volume kind, arity and descent rule, under rigid transforms (with scale and
mirror), for touching and coplanar contact, and after refitting deformed meshes; detection finds
a pair exactly when there is one; time-critical queries never miss a contact."""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.collision import (Budget, TriangleMesh, build_bvh, collide,
                                     collision_detection, collision_determination,
                                     triangles_overlap)
from physanim.core.collision.shapes import grid_mesh, sphere_mesh
from physanim.core.errors import PhysanimError
from physanim.core.transforms import compose, transform_points

KINDS = ["sphere", "aabb", "obb", "obb_hull", "obb_triangles", "obb6", "kdop14", "kdop18",
         "kdop26"]
BUILDS = [("topdown", {"split": "center"}), ("topdown", {"split": "median"}),
          ("bottomup", {}), ("incremental", {})]


def brute_force(mesh_a, mesh_b, matrix_a=None, matrix_b=None):
    """All overlapping triangle pairs, B mapped into A's frame exactly as the query does."""
    rel = np.eye(4)
    if matrix_a is not None or matrix_b is not None:
        ma = np.eye(4) if matrix_a is None else matrix_a
        mb = np.eye(4) if matrix_b is None else matrix_b
        from physanim.core.transforms import inverse_affine
        rel = inverse_affine(ma) @ mb
    vb = mesh_b.vertices if np.array_equal(rel, np.eye(4)) else transform_points(rel,
                                                                                 mesh_b.vertices)
    ta, tb = mesh_a.triangle_vertices, vb[mesh_b.triangles]
    i, j = np.meshgrid(np.arange(len(ta)), np.arange(len(tb)), indexing="ij")
    i, j = i.ravel(), j.ravel()
    ok = triangles_overlap(ta[i], tb[j])
    return np.stack([i[ok], j[ok]], axis=1)


def _bumpy(seed, subdivisions=2, name="bumpy"):
    mesh = sphere_mesh(subdivisions)
    rng = np.random.default_rng(seed)
    return TriangleMesh(mesh.vertices * rng.uniform(0.85, 1.15, (mesh.vertex_count, 1)),
                        mesh.triangles, name)


def _scenes():
    """(name, mesh A, mesh B, matrix A, matrix B): crossing, touching, coplanar, scaled,
    mirrored and far-apart configurations."""
    rng = np.random.default_rng(42)
    a, b = _bumpy(1), _bumpy(2)
    grid = grid_mesh(13, amplitude=0.08)
    flat = grid_mesh(13)
    shifted = TriangleMesh(flat.vertices + [1.0 / 24, 1.0 / 48, 0.0], flat.triangles, "shifted")
    out = []
    for k in range(3):
        q = rng.normal(size=4)
        out.append((f"spheres{k}", a, b, compose(rng.normal(size=3) * 0.2, q / np.linalg.norm(q),
                                                 np.ones(3)),
                    compose(rng.normal(size=3) * 0.2 + [1.2, 0, 0], [1, 0, 0, 0], np.ones(3))))
    out.append(("scaled-mirrored", a, b, compose([0, 0, 0], [1, 0, 0, 0], [1.3, 1.3, -1.3]),
                compose([1.5, 0.3, 0], [0.9, 0.1, 0.3, 0.2], [0.7, 0.7, 0.7])))
    out.append(("same-mesh-touching", grid, grid, None, None))  # every neighbour touches
    out.append(("coplanar-offset", flat, shifted, None, None))  # coplanar overlaps, exact
    out.append(("grid-crossing", grid, grid, None,
                 compose([0.3, 0.2, -0.4], [np.cos(0.6), np.sin(0.6), 0, 0], np.ones(3))))
    out.append(("apart", a, b, None, compose([5, 0, 0], [1, 0, 0, 0], np.ones(3))))
    return out


SCENES = _scenes()


@pytest.fixture(scope="module")
def truth():
    return {name: brute_force(ma, mb, xa, xb) for name, ma, mb, xa, xb in SCENES}


def test_scenes_cover_the_hard_cases(truth):
    assert all(len(truth[n]) > 20 for n in truth if n not in ("apart",))
    assert len(truth["apart"]) == 0
    grid = SCENES[4][1]
    # touching a copy of itself: every triangle meets itself and all its neighbours
    assert len(truth["same-mesh-touching"]) > 10 * grid.triangle_count


# the hull-fitted OBB differs from the others only in its fit (a quickhull per node): one builder
COMBOS = [(kind, method, options) for kind in KINDS for method, options in BUILDS
          if kind != "obb_hull" or options.get("split") == "center"]


@pytest.mark.parametrize("kind,method,options", COMBOS, ids=lambda x: str(x))
def test_determination_equals_brute_force(truth, kind, method, options):
    trees = {}

    def tree(mesh, wide):
        key = (id(mesh), wide)
        if key not in trees:
            trees[key] = build_bvh(mesh, kind, method, arity=4 if wide else 2,
                                   leaf_size=2 if wide else 4, **options)
        return trees[key]

    for i, (name, ma, mb, xa, xb) in enumerate(SCENES):
        descend = "larger" if i % 3 else "both"
        ta, tb = tree(ma, False), tree(mb, True)
        if i % 2:  # B's tree first: the binary tree descends against the 4-ary one
            got = collide(tb, ta, xb, xa, descend=descend)
            pairs = got.pairs[:, ::-1]
            pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
            moved = ta
        else:
            got = collide(ta, tb, xa, xb, descend=descend)
            pairs, moved = got.pairs, tb
        assert got.complete and not len(got.unresolved)
        np.testing.assert_array_equal(pairs, truth[name], err_msg=f"{name} {kind}")
        assert got.n_p >= len(truth[name]) and got.n_v > 0
        assert got.n_u == 0 if xa is None and xb is None else 0 < got.n_u <= moved.node_count


@pytest.mark.parametrize("kind", ["sphere", "aabb", "obb", "kdop18"])
def test_detection_finds_a_pair_exactly_when_there_is_one(truth, kind):
    for name, ma, mb, xa, xb in SCENES:
        ta, tb = build_bvh(ma, kind), build_bvh(mb, kind, "bottomup")
        got = collision_detection(ta, tb, xa, xb)
        assert got.hit == (len(truth[name]) > 0)
        if got.hit:
            assert len(got.pairs) == 1
            assert (truth[name] == got.pairs[0]).all(axis=1).any()
            full = collision_determination(ta, tb, xa, xb)
            assert got.n_v + got.n_p <= full.n_v + full.n_p


def test_both_descent_rules_and_all_pairs_agree_with_swapped_roles(truth):
    _, ma, mb, xa, xb = SCENES[0]
    ta, tb = build_bvh(ma, "obb"), build_bvh(mb, "obb")
    ab = collide(ta, tb, xa, xb).pairs
    ba = collide(tb, ta, xb, xa).pairs[:, ::-1]
    np.testing.assert_array_equal(ab, ba[np.lexsort((ba[:, 1], ba[:, 0]))])


@pytest.mark.parametrize("kind", ["aabb", "obb", "sphere", "kdop14"])
def test_refit_keeps_determination_exact(kind):
    rng = np.random.default_rng(5)
    a, b = _bumpy(3), grid_mesh(15, size=2.0, amplitude=0.1)
    xb = compose([-1.0, -1.0, 0.0], [1, 0, 0, 0], np.ones(3))
    ta, tb = build_bvh(a, kind), build_bvh(b, kind, "bottomup", arity=4)
    for step in range(3):
        v = b.vertices.copy()
        v[:, 2] += 0.6 * np.sin(3.0 * v[:, 0] + step) * np.cos(2.0 * v[:, 1])
        v += rng.normal(size=v.shape) * 0.01
        tb, n_u = tb.refit(v)
        assert n_u > 0
        want = brute_force(a, tb.mesh, None, xb)
        got = collide(ta, tb, None, xb)
        np.testing.assert_array_equal(got.pairs, want)
        assert len(want) > 0


@pytest.mark.parametrize("kind", ["aabb", "obb", "sphere"])
def test_time_critical_queries_never_miss(truth, kind):
    for name, ma, mb, xa, xb in SCENES:
        ta, tb = build_bvh(ma, kind), build_bvh(mb, kind)
        want = {tuple(p) for p in truth[name]}
        full = collide(ta, tb, xa, xb)
        for limit in (0, 1, 5, 20, 100, 1000, 10 ** 9):
            got = collide(ta, tb, xa, xb, budget=Budget(max_tests=limit))
            assert got.n_v + got.n_p <= limit
            confirmed = {tuple(p) for p in got.pairs}
            assert confirmed <= want
            # every real contact is confirmed or inside an unresolved node pair
            covered = confirmed | _pairs_under(ta, tb, got.unresolved, want)
            assert covered == want, (name, limit)
            if want:
                assert got.possible_contact
            if got.complete:
                assert got.possible_contact == bool(want)
                np.testing.assert_array_equal(got.pairs, full.pairs)
        assert collide(ta, tb, xa, xb, budget=Budget(seconds=0.0)).possible_contact
        detect = collide(ta, tb, xa, xb, first=True, budget=Budget(max_tests=3))
        assert detect.possible_contact or not want


def _pairs_under(ta, tb, node_pairs, wanted):
    """The wanted triangle pairs lying under any of the given (node of A, node of B) pairs."""
    out = set()
    for na, nb in node_pairs:
        sa = set(ta.tri_order[ta.node_first[na]:ta.node_first[na] + ta.node_tri_count[na]])
        sb = set(tb.tri_order[tb.node_first[nb]:tb.node_first[nb] + tb.node_tri_count[nb]])
        out |= {p for p in wanted if p[0] in sa and p[1] in sb}
    return out


def test_budget_in_seconds_refines_progressively():
    a, b = grid_mesh(40, amplitude=0.05), grid_mesh(40, amplitude=0.05)
    xb = compose([0, 0, 0.002], [1, 0, 0, 0], np.ones(3))
    ta, tb = build_bvh(a, "aabb"), build_bvh(b, "aabb")
    coarse = collide(ta, tb, None, xb, budget=Budget(max_tests=50))
    assert not coarse.complete and coarse.possible_contact
    # breadth first: what is left are shallow node pairs, covering the whole contact region
    assert len(coarse.unresolved) > 0
    done = collide(ta, tb, None, xb, budget=Budget(seconds=60.0))
    assert done.complete and not len(done.unresolved)


def test_query_input_errors():
    a = build_bvh(_bumpy(1), "obb")
    b = build_bvh(_bumpy(2), "aabb")
    with pytest.raises(ValueError, match="same bounding volume"):
        collide(a, b)
    with pytest.raises(ValueError, match="descend"):
        collide(a, a, descend="random")
    shear = np.eye(4)
    shear[0, 1] = 0.3
    with pytest.raises(PhysanimError, match="must be rigid"):
        collide(a, a, shear)
    bad = np.eye(4)
    bad[0, 3] = np.nan
    with pytest.raises(ValueError, match="finite"):
        collide(a, a, None, bad)
    with pytest.raises(ValueError, match="max_tests"):
        Budget(max_tests=-1)
    with pytest.raises(ValueError, match="seconds"):
        Budget(seconds=float("nan"))
