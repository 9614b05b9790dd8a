"""Helpers shared by the core test files (imported as ``physanim.tests.core.helpers``)."""
from __future__ import annotations

import math

import numpy as np

from physanim.core.collision.shapes import grid_mesh
from physanim.core.contact import ColliderFrame
from physanim.core.particles import ParticleModelBuilder


def grid(nx: int, ny: int, size: float = 1.0):
    """Flat grid of nx * ny vertices in z = 0: positions, edges, triangles and quad loops
    (loop_start, loop_total, loop_vertices)."""
    xs, ys = np.meshgrid(np.linspace(0.0, size, nx), np.linspace(0.0, size, ny))
    x = np.stack([xs.ravel(), ys.ravel(), np.zeros(nx * ny)], axis=1)
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1))
    a = (j * nx + i).ravel()
    quads = np.stack([a, a + 1, a + nx + 1, a + nx], axis=1)
    triangles = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    edges = np.concatenate([quads[:, [0, 1]], quads[:, [1, 2]], quads[:, [2, 3]], quads[:, [3, 0]]])
    return x, edges, triangles, 4 * np.arange(len(quads)), np.full(len(quads), 4), quads.ravel()


def particle_model(*settings, seed=0):
    """A particle model with one emitter per :class:`EmitterSettings` given."""
    builder = ParticleModelBuilder(seed)
    for s in settings:
        builder.add_emitter(s)
    return builder.finalize()


def place(state, x, v, emitter=0, mass=1.0, life=1e9):
    """Put particles at x with velocities v (size 0.05 m) into ``state``."""
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    v = np.atleast_2d(np.asarray(v, dtype=np.float64))
    n = len(x)
    return state.append(emitter, x, v, np.full(n, mass), np.zeros(n), np.full(n, life),
                        np.full(n, 0.05))


def translation(x=0.0, y=0.0, z=0.0) -> np.ndarray:
    """4 x 4 translation matrix."""
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def rotation(axis, angle) -> np.ndarray:
    """4 x 4 rotation about an axis (Rodrigues)."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    m = np.eye(4)
    m[:3, :3] = np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k
    return m


def sheet(n: int, size: float):
    """A flat n x n vertex grid of side ``size`` centred on the origin in z = 0, normals +z:
    (vertices, triangles)."""
    mesh = grid_mesh(n, size)
    return mesh.vertices - [size / 2, size / 2, 0.0], mesh.triangles


def mesh_collider(name, verts, tris, m0=None, m1=None, verts1=None, **kw) -> ColliderFrame:
    """A MESH collider: vertices ``verts`` (moving to ``verts1``), matrix m0 -> m1 (identity,
    still by default); ``kw`` are ColliderFrame settings."""
    m0 = np.eye(4) if m0 is None else m0
    m1 = m0 if m1 is None else m1
    return ColliderFrame(name, "MESH", m0, m1, vertices0=verts,
                         vertices1=verts if verts1 is None else verts1, triangles=tris, **kw)


def implicit_step_times(monkeypatch) -> list:
    """A list that receives the time t of every implicit (Baraff-Witkin) step taken from now
    on in the test (a sub-step solved again appears once more)."""
    from physanim.core.springs import implicit

    times = []
    step = implicit.BaraffWitkin._step_impl

    def counted(self, system, t, y, h):
        times.append(t)
        return step(self, system, t, y, h)

    monkeypatch.setattr(implicit.BaraffWitkin, "_step_impl", counted)
    return times
