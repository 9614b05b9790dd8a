"""Wind on a mesh's faces: pressure on the side facing the wind plus skin friction along it."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import cross
from ..forces import ParticleView, Wind
from ..forces.springs import scatter_add


@dataclass(frozen=True)
class FaceWind:
    """Wind on faces: with p = strength (d + gusts) [N/m^2] the pressure vector, a triangle of
    area A and unit normal n gets f = A [(p . n) n + c_t (p - (p . n) n)]: the pressure on the
    side facing the wind plus skin friction along it (c_t = SKIN_FRICTION; it is what streams a
    flag out). A third goes to each corner."""

    SKIN_FRICTION = 0.25

    triangles: np.ndarray
    wind: Wind

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        tri = self.triangles
        a, b, c = p.x[tri[:, 0]], p.x[tri[:, 1]], p.x[tri[:, 2]]
        doubled = cross(b - a, c - a)  # |doubled| = 2 A, direction = normal
        w = self.wind
        pressure = np.broadcast_to(np.asarray(w.direction) * w.strength, doubled.shape)
        if w.noise:
            pressure = pressure + (w.strength * w.noise) * w.field((a + b + c) / 3.0, p.t)
        norm = np.sqrt(np.einsum("ij,ij->i", doubled, doubled))
        area = 0.5 * norm
        n = doubled / np.where(norm > 0, norm, 1.0)[:, None]
        normal = np.einsum("ij,ij->i", pressure, n)[:, None] * n
        f = (area / 3.0)[:, None] * (normal + self.SKIN_FRICTION * (pressure - normal))
        for k in range(3):
            scatter_add(f_out, tri[:, k], f)
