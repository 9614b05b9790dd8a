"""A rigid mesh's parts kept for the contact search: its edges and its vertices by cells."""
from __future__ import annotations

import numpy as np
import pytest

from physanim.core.rigid.mesh_contacts import MeshCache
from physanim.core.rigid.mesh_parts import MeshEdges, VertexCells

TETRAHEDRON = (np.array([(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 2)], float),
               np.array([(0, 2, 1), (0, 1, 3), (1, 2, 3), (0, 3, 2)]))


def test_a_tetrahedrons_edges_are_its_six_each_once_and_three_end_at_each_corner():
    vertices, triangles = TETRAHEDRON
    edges = MeshEdges.of(vertices, triangles)
    assert sorted(map(tuple, edges.pairs.tolist())) == [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3),
                                                          (2, 3)]
    assert edges.longest == pytest.approx(np.sqrt(5.0))  # (1, 0, 0) - (0, 0, 2)
    which, e = edges.touching(np.array([3, 0]))
    for k, v in enumerate((3, 0)):
        ends = edges.pairs[e[which == k]]
        assert len(ends) == 3 and np.all((ends == v).any(axis=1))


@pytest.mark.parametrize("seed", range(4))
def test_vertex_cells_find_exactly_the_vertices_within_each_radius(seed):
    rng = np.random.default_rng(seed)
    vertices = rng.uniform(-5.0, 5.0, (2000, 3))
    cells = VertexCells(vertices)
    for _ in range(3):  # several searches, radii of several cell sizes
        centres = rng.uniform(-6.0, 6.0, (25, 3))
        radii = rng.uniform(0.05, 2.5, 25) * rng.choice([0.1, 1.0], 25)
        k, v = cells.near(centres, radii)
        found = set(zip(k.tolist(), v.tolist()))
        distance = np.linalg.norm(vertices[None] - centres[:, None], axis=2)
        assert found == set(zip(*np.nonzero(distance < radii[:, None])))


def test_a_meshs_parts_are_built_once_while_its_values_stay_the_same():
    """A frame's inputs are new arrays: the same values keep the hierarchy, edges and cells;
    moved vertices rebuild them."""
    vertices, triangles = TETRAHEDRON
    cache = MeshCache()
    first = cache.shape("Peg", vertices.copy(), triangles.copy())
    again = cache.shape("Peg", vertices.copy(), triangles.copy())
    assert again.bvh is first.bvh and again.cells is first.cells and again.edges is first.edges
    moved = cache.shape("Peg", vertices * 2.0, triangles.copy())
    assert moved.bvh is not first.bvh and moved.cells is not first.cells
    assert moved.hi[2] == pytest.approx(4.0)
