"""Forces particles have beyond the shared field forces (:mod:`physanim.core.forces`): damped
springs between particles of the same emitter."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..forces import ParticleView


@dataclass(frozen=True)
class DampedSprings:
    """Damped springs between particles i and j (indices into the current arrays).

    f_i = -[ks (|l| - r) + kd (dl/dt . l)/|l|] l/|l|, l = x_i - x_j; f_j = -f_i (Witkin & Baraff).

    Args: i, j: (s,) int indices. stiffness: ks [N/m]. damping: kd [N s/m]. rest: (s,) [m].
    """

    i: np.ndarray
    j: np.ndarray
    stiffness: float
    damping: float
    rest: np.ndarray

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        if len(self.i) == 0:
            return
        l = p.x[self.i] - p.x[self.j]
        ldot = p.v[self.i] - p.v[self.j]
        length = np.linalg.norm(l, axis=1)
        safe = np.where(length > 1e-12, length, 1.0)
        u = l / safe[:, None]
        mag = self.stiffness * (length - self.rest) + self.damping * np.einsum("ij,ij->i", ldot, u)
        f = -mag[:, None] * u
        np.add.at(f_out, self.i, f)
        np.add.at(f_out, self.j, -f)
