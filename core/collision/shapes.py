"""Procedural triangle meshes for tests, benchmarks and demos: grids, spheres, boxes, tori,
cylinders."""
from __future__ import annotations

import numpy as np

from .mesh import TriangleMesh


def grid_mesh(n: int, size: float = 1.0, amplitude: float = 0.0, waves=(6.0, 5.0),
              name: str = "grid") -> TriangleMesh:
    """An n x n vertex grid over [0, size]^2 in the xy plane, 2 (n - 1)^2 triangles, normals +z.

    Args:
        amplitude: height of the bumps z = amplitude sin(wx x / size) cos(wy y / size) [m].
        waves: (wx, wy) angular frequencies of the bumps over the grid.
    """
    if n < 2:
        raise ValueError(f"a grid needs n >= 2 vertices per side (got {n})")
    s = np.linspace(0.0, size, n)
    x, y = np.meshgrid(s, s)
    z = amplitude * np.sin(waves[0] * x / size) * np.cos(waves[1] * y / size)
    v = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel()
    tri = np.concatenate([np.stack([a, b, d], axis=1), np.stack([a, d, c], axis=1)])
    return TriangleMesh(v, tri, name)


def sphere_mesh(subdivisions: int = 2, radius: float = 1.0, name: str = "sphere") -> TriangleMesh:
    """Icosphere: an icosahedron with each triangle split in 4, ``subdivisions`` times
    (20 * 4^subdivisions triangles, outward winding, welded vertices)."""
    t = (1.0 + 5.0 ** 0.5) / 2.0
    v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], float)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                  [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                  [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                  [8, 6, 7], [9, 8, 1]])
    for _ in range(subdivisions):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(edges, axis=0, return_inverse=True)
        mid = len(v) + inv.reshape(3, -1).T  # (m, 3): midpoints of edges 01, 12, 20
        v = np.concatenate([v, 0.5 * (v[uniq[:, 0]] + v[uniq[:, 1]])])
        a, b, c = f.T
        ab, bc, ca = mid.T
        f = np.concatenate([np.stack(x, axis=1) for x in
                            ((a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca))])
    v = radius * v / np.linalg.norm(v, axis=1, keepdims=True)
    return TriangleMesh(v, f, name)


def box_mesh(half=(1.0, 1.0, 1.0), name: str = "box") -> TriangleMesh:
    """Axis-aligned box centred at the origin, 12 triangles wound outward."""
    h = np.asarray(half, dtype=np.float64)
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * h
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return TriangleMesh(v, f, name)


def torus_mesh(major: float = 1.0, minor: float = 0.25, segments: int = 32, sides: int = 12,
               name: str = "torus") -> TriangleMesh:
    """A closed torus about the z axis: ring radius ``major``, tube radius ``minor`` [m],
    ``segments`` around the ring, ``sides`` around the tube; wound outward."""
    if not 0.0 < minor < major:
        raise ValueError(f"a torus needs 0 < minor < major (got {minor}, {major})")
    u = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)[:, None]
    v = np.linspace(0.0, 2.0 * np.pi, sides, endpoint=False)[None, :]
    ring = major + minor * np.cos(v)
    verts = np.stack(np.broadcast_arrays(ring * np.cos(u), ring * np.sin(u),
                                         minor * np.sin(v)), axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(segments), np.arange(sides), indexing="ij")
    a = i * sides + j
    b = (i + 1) % segments * sides + j
    c = (i + 1) % segments * sides + (j + 1) % sides
    d = i * sides + (j + 1) % sides
    tri = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                          np.stack([a, c, d], -1).reshape(-1, 3)])
    return TriangleMesh(verts, tri, name)


def cylinder_mesh(radius: float = 1.0, half_height: float = 1.0, segments: int = 24,
                  name: str = "cylinder") -> TriangleMesh:
    """A closed cylinder about the z axis (|z| <= half_height), caps fanned from their
    centres; wound outward."""
    t = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    rim = np.stack([radius * np.cos(t), radius * np.sin(t), np.zeros(segments)], axis=1)
    verts = np.concatenate([rim - (0, 0, half_height), rim + (0, 0, half_height),
                            [(0.0, 0.0, -half_height), (0.0, 0.0, half_height)]])
    k = np.arange(segments)
    k1 = (k + 1) % segments
    lo, hi, bottom, top = k, segments + k, 2 * segments, 2 * segments + 1
    tri = np.concatenate([np.stack([lo, k1, segments + k1], 1), np.stack([lo, segments + k1, hi], 1),
                          np.stack([np.full(segments, bottom), k1, lo], 1),
                          np.stack([np.full(segments, top), hi, segments + k1], 1)])
    return TriangleMesh(verts, tri, name)
