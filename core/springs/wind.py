"""Wind on a mesh's faces: the air's pressure on the side facing it plus skin friction along it,
from the face's velocity relative to the air (a face moving with the wind feels none of it)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import cross, divide_rows, scale_rows
from ..forces import ParticleView, Wind
from ..forces.springs import flat_index, scatter_add


@dataclass(frozen=True)
class FaceWind:
    """Wind on faces as quadratic drag on each face's velocity relative to the air.

    The wind's pressure vector p = strength (d + gusts) [N/m^2] is what still faces feel: the
    air's velocity is the one that gives it, U = p / sqrt(K |p|) (so that K |U| U = p), with
    K = 1/2 rho C_d (sea-level air, a flat plate's drag coefficient). A triangle of area A, unit
    normal n and velocity w (the mean of its corners') feels the pressure P = K |u| u of the
    relative air velocity u = U - w, as f = A [(P . n) n + c_t (P - (P . n) n)]: pressure on the
    side facing the air plus skin friction along it (c_t = SKIN_FRICTION: it is what streams a
    flag out). A third goes to each corner. Still, a face feels exactly p; moving with the air,
    nothing; flapping against it, the air damps it (about 90 1/s for a light flag in a
    breeze — far too stiff for an explicit term, so :meth:`linearize` gives the implicit solve
    its Jacobian in the velocities).
    """

    SKIN_FRICTION = 0.25
    AIR_DENSITY = 1.225  # [kg/m^3]
    DRAG_COEFFICIENT = 1.2  # a flat plate across the flow
    K = 0.5 * AIR_DENSITY * DRAG_COEFFICIENT

    triangles: np.ndarray
    wind: Wind

    def __post_init__(self):
        object.__setattr__(self, "_flat", flat_index(np.asarray(self.triangles).T.ravel()))
        object.__setattr__(self, "_last", [None])

    def _faces(self, p: ParticleView):
        """Per face: area (m,), unit normal (m, 3) and the relative air velocity u (m, 3) —
        the last ones again at the same state (an implicit step asks for the forces and then
        the Jacobian at its start; the gusts are most of the cost)."""
        last = self._last[0]
        if last is not None and last[0] == p.t and np.array_equal(last[1], p.x) \
                and np.array_equal(last[2], p.v):
            return last[3]
        faces = self._compute(p)
        self._last[0] = (p.t, p.x.copy(), p.v.copy(), faces)
        return faces

    def _compute(self, p: ParticleView):
        tri = self.triangles
        a, b, c = p.x[tri[:, 0]], p.x[tri[:, 1]], p.x[tri[:, 2]]
        doubled = cross(b - a, c - a)  # |doubled| = 2 A, direction = normal
        w = self.wind
        pressure = np.broadcast_to(np.asarray(w.direction) * w.strength, doubled.shape)
        if w.noise:
            pressure = pressure + (w.strength * w.noise) * w.field((a + b + c) / 3.0, p.t)
        size = np.sqrt(np.einsum("ij,ij->i", pressure, pressure))
        air = divide_rows(pressure, np.sqrt(self.K * np.where(size > 0.0, size, 1.0)))
        v = p.v
        u = air - (v[tri[:, 0]] + v[tri[:, 1]] + v[tri[:, 2]]) / 3.0
        norm = np.sqrt(np.einsum("ij,ij->i", doubled, doubled))
        n = divide_rows(doubled, np.where(norm > 0, norm, 1.0))
        return 0.5 * norm, n, u

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        area, n, u = self._faces(p)
        speed = np.sqrt(np.einsum("ij,ij->i", u, u))
        pressure = scale_rows(u, self.K * speed)
        normal = scale_rows(n, np.einsum("ij,ij->i", pressure, n))
        f = scale_rows(normal + self.SKIN_FRICTION * (pressure - normal), area / 3.0)
        scatter_add(f_out, None, np.concatenate([f, f, f]), self._flat)

    def linearize(self, p: ParticleView) -> LinearizedFaces:
        """df/dv at ``p``: every corner's force depends on the face's mean velocity, so each
        face couples its three corners by the block -(A / 9) s B, with B = (1 - c_t) n n^T +
        c_t I and s = 2 K |u|, the drag's steepest slope (along u; across it, half that): a
        symmetric negative semi-definite Jacobian, as conjugate gradients needs, that never
        under-damps. The positions' part (the faces turning) is left to the explicit forces."""
        area, n, u = self._faces(p)
        s = (2.0 * self.K / 9.0) * area * np.sqrt(np.einsum("ij,ij->i", u, u))
        return LinearizedFaces(self.triangles, n, s, self.SKIN_FRICTION, self._flat)


@dataclass(frozen=True)
class LinearizedFaces:
    """df/dv = -s_m B_m on every pair of corners (i, j) of face m, B_m = (1 - c_t) n n^T +
    c_t I; no df/dx."""

    triangles: np.ndarray
    normal: np.ndarray
    scale: np.ndarray
    skin: float
    flat: np.ndarray

    @property
    def clique(self) -> np.ndarray:
        return self.triangles

    def add_to(self, builder, cx: float, cv: float) -> None:
        """cv df/dv: the block -cv s B on every pair of a face's corners."""
        if cv:
            n = self.normal
            blocks = ((1.0 - self.skin) * self.scale)[:, None, None] * (n[:, :, None] * n[:, None, :])
            blocks += (self.skin * self.scale)[:, None, None] * np.eye(3)
            builder.add_shared(self.triangles, blocks, -cv)

    def product(self, cx: float, cv: float, u: np.ndarray, out: np.ndarray) -> None:
        """out += cv df/dv u, matrix-free."""
        tri = self.triangles
        total = u[tri[:, 0]] + u[tri[:, 1]] + u[tri[:, 2]]
        along = scale_rows(self.normal, np.einsum("ij,ij->i", total, self.normal))
        w = scale_rows((1.0 - self.skin) * along + self.skin * total, -cv * self.scale)
        scatter_add(out, None, np.concatenate([w, w, w]), self.flat)
