"""The collision library against Blender's own C BVH (``mathutils.bvhtree.BVHTree.overlap``) on
real meshes: Suzanne, subdivided, under rotations, scales and offsets.

Blender's overlap skips pairs that only touch or are coplanar, ours reports them (exactly);
random rotations and offsets keep every contact a proper crossing, where both must agree.
"""
from __future__ import annotations

import importlib

import bmesh
import numpy as np
import pytest
from mathutils.bvhtree import BVHTree


def _suzanne(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    bm = bmesh.new()
    bmesh.ops.create_monkey(bm)
    if subdivisions:
        bmesh.ops.subdivide_edges(bm, edges=bm.edges[:], cuts=subdivisions, use_grid_fill=True)
    bmesh.ops.triangulate(bm, faces=bm.faces[:])
    verts = np.array([v.co[:] for v in bm.verts])
    tris = np.array([[v.index for v in f.verts] for f in bm.faces])
    bm.free()
    return verts, tris


def _matrix(rng, scale: float) -> np.ndarray:
    """A random rigid transform with uniform scale, in float64 (mathutils matrices are float32,
    which a rigidity check rightly refuses)."""
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    rot = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                    [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                    [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    m = np.eye(4)
    m[:3, :3] = scale * rot
    m[:3, 3] = rng.uniform(-0.6, 0.6, 3)
    return m


@pytest.mark.parametrize("kind", ["obb", "aabb", "sphere", "kdop18"])
@pytest.mark.parametrize("subdivisions", [0, 1])
def test_overlapping_triangle_pairs_match_blenders_bvhtree(physanim_ext, kind, subdivisions):
    collision = importlib.import_module(f"{physanim_ext.__name__}.core.collision")
    verts, tris = _suzanne(subdivisions)
    mesh = collision.TriangleMesh(verts, tris, "Suzanne")
    tree = collision.build_bvh(mesh, kind, "topdown")
    rng = np.random.default_rng(7 + subdivisions)
    compared = 0
    for _ in range(4):
        ma, mb = _matrix(rng, 1.0), _matrix(rng, rng.uniform(0.7, 1.3))
        ours = collision.collision_determination(tree, tree, ma, mb)
        world_a = verts @ ma[:3, :3].T + ma[:3, 3]
        world_b = verts @ mb[:3, :3].T + mb[:3, 3]
        blender_a = BVHTree.FromPolygons(world_a.tolist(), tris.tolist(), all_triangles=True)
        blender_b = BVHTree.FromPolygons(world_b.tolist(), tris.tolist(), all_triangles=True)
        theirs = sorted(blender_a.overlap(blender_b))
        assert [tuple(p) for p in ours.pairs.tolist()] == theirs
        assert ours.n_v > 0 and ours.n_p >= len(theirs)
        compared += len(theirs)
    assert compared > 50  # the placements really intersect
