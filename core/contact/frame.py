"""A collider as the contact layer sees it during one frame interval: shape, motion, surface
properties, validated on construction."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..validate import matrix, non_negative

COLLIDER_SHAPES = ("HALF_SPACE", "PLANE", "SPHERE", "BOX", "MESH")


@dataclass(frozen=True)
class ColliderFrame:
    """A collider during one frame interval.

    Shapes live in the object's local space: ``HALF_SPACE`` is z <= 0 (an infinite ground),
    ``PLANE`` the two-sided square |x|, |y| <= 1 at z = 0, ``SPHERE`` the unit sphere and ``BOX``
    the cube |x|, |y|, |z| <= 1 — Blender's default primitives — mapped by the world matrix.
    ``MESH`` is any triangle mesh (open, single-sided ones too: both faces collide), whose local
    vertices may move during the interval (a deforming mesh), mapped by the same world matrix.

    Args:
        name: object name for messages.
        shape: one of :data:`COLLIDER_SHAPES`.
        matrix0, matrix1: (4, 4) world matrices at the interval's start and end.
        matrices: optional (k + 1, 4, 4) sub-frame samples at s = 0, 1/k, ..., 1.
        restitution: k_r in [0, 1]: normal speed kept after a bounce.
        friction: Coulomb coefficient mu >= 0.
        thickness: the surface is grown outwards by this much [m] (a particle's radius, a
            cloth's half-thickness), so points stop that far from the shape.
        vertices0, vertices1: ``MESH`` only: (n, 3) local vertex positions [m] at the interval's
            start and end (equal for a mesh that does not deform); positions in between are
            interpolated linearly.
        triangles: ``MESH`` only: (m, 3) vertex indices (the winding gives the face normals).
    """

    name: str
    shape: str
    matrix0: np.ndarray
    matrix1: np.ndarray
    restitution: float = 0.5
    friction: float = 0.2
    matrices: np.ndarray | None = None
    thickness: float = 0.0
    vertices0: np.ndarray | None = None
    vertices1: np.ndarray | None = None
    triangles: np.ndarray | None = None

    def __post_init__(self):
        owner = f'collider "{self.name}"'
        non_negative(owner, thickness=self.thickness)
        if self.shape not in COLLIDER_SHAPES:
            raise ValueError(f"{owner}: shape must be one of {COLLIDER_SHAPES} (got {self.shape!r})")
        non_negative(owner, restitution=self.restitution, friction=self.friction)
        if self.restitution > 1.0:
            raise ValueError(f"{owner}: restitution must be <= 1 (got {self.restitution})")
        for key in ("matrix0", "matrix1"):
            m = matrix(owner, key, getattr(self, key))
            if abs(np.linalg.det(m[:3, :3])) < 1e-12:
                raise ValueError(f"{owner}: {key} is singular (a zero scale flattens the collider)")
            object.__setattr__(self, key, m)
        if self.matrices is not None:
            for k, m in enumerate(self.matrices):
                if abs(np.linalg.det(matrix(owner, f"sub-frame matrix {k}", m)[:3, :3])) < 1e-12:
                    raise ValueError(f"{owner}: sub-frame matrix {k} is singular (zero scale)")
        if self.shape == "MESH":
            self._validate_mesh(owner)
        elif any(getattr(self, k) is not None for k in ("vertices0", "vertices1", "triangles")):
            raise ValueError(f"{owner}: vertices and triangles are for MESH colliders only "
                             f"(shape is {self.shape})")

    def same_as(self, other: ColliderFrame) -> bool:
        """Whether ``other`` describes the same collider in the same place: a still collider's
        next frame interval, whose path can be the one already made."""
        if other is self:
            return True
        if (self.name, self.shape, self.restitution, self.friction, self.thickness) != (
                other.name, other.shape, other.restitution, other.friction, other.thickness):
            return False
        return all(_same_array(getattr(self, k), getattr(other, k)) for k in _ARRAYS)

    def _validate_mesh(self, owner: str) -> None:
        given = (self.vertices0, self.vertices1)
        verts = []
        for key, value in zip(("vertices0", "vertices1"), given):
            if value is None:
                raise ValueError(f"{owner}: a MESH collider needs {key}")
            if key == "vertices1" and value is given[0]:  # one shape over the interval (a
                v = verts[0]  # rigid body's): checked once, one array (its path then knows
                # it does not deform without comparing them)
            else:
                v = np.array(value, dtype=np.float64)
                if v.ndim != 2 or v.shape[1] != 3:
                    raise ValueError(f"{owner}: {key} must be an (n, 3) array (got shape "
                                     f"{v.shape})")
                bad = ~np.isfinite(v).all(axis=1)
                if bad.any():
                    i = int(np.argmax(bad))
                    raise ValueError(f"{owner}: {key} vertex {i} is not finite: "
                                     f"{v[i].tolist()}")
                v.setflags(write=False)
            object.__setattr__(self, key, v)
            verts.append(v)
        if len(verts[0]) != len(verts[1]):
            raise ValueError(f"{owner}: vertices0 has {len(verts[0])} vertices but vertices1 has "
                             f"{len(verts[1])}: a deforming mesh must keep its vertex count")
        if self.triangles is None:
            raise ValueError(f"{owner}: a MESH collider needs triangles")
        t = np.asarray(self.triangles)
        if t.size == 0:
            raise ValueError(f"{owner}: the mesh has no triangles to collide with")
        if t.ndim != 2 or t.shape[1] != 3 or t.dtype.kind not in "iu":
            raise ValueError(f"{owner}: triangles must be an (m, 3) integer array "
                             f"(got shape {t.shape}, dtype {t.dtype})")
        t = t.astype(np.int64)
        out = (t < 0) | (t >= len(verts[0]))
        if out.any():
            i = int(np.argmax(out.any(axis=1)))
            raise ValueError(f"{owner}: triangle {i} refers to vertex {t[i].tolist()} but the "
                             f"mesh has {len(verts[0])} vertices")
        t.setflags(write=False)
        object.__setattr__(self, "triangles", t)


_ARRAYS = ("matrix0", "matrix1", "matrices", "vertices0", "vertices1", "triangles")


def same_frames(a, b) -> bool:
    """Whether two sequences of colliders' frames describe the same colliders in the same
    places, one by one (:meth:`ColliderFrame.same_as`)."""
    return len(a) == len(b) and all(x.same_as(y) for x, y in zip(a, b))


def _same_array(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    if a is None or b is None:
        return a is b
    return a is b or (a.shape == b.shape and bool(np.array_equal(a, b)))
