"""Strain limiting (Provot 1995, "Deformation constraints in a mass-spring model"): after a
step, springs stretched beyond ``(1 + max_stretch)`` times their rest length are pulled back by
moving their ends towards each other (pinned ends stay), a few Jacobi sweeps, and the velocities
take the same correction so the next step starts consistent. It keeps soft, cheap-to-solve
springs from looking like rubber under load."""
from __future__ import annotations

import numpy as np

SWEEPS = 40  # Jacobi sweeps per sub-step at most (stops early once every spring is within)
RELAXATION = 0.8  # under-relaxation keeps the Jacobi averaging from overshooting


def limit_strain(x: np.ndarray, v: np.ndarray, i: np.ndarray, j: np.ndarray, rest: np.ndarray,
                 inv_mass: np.ndarray, max_stretch: float, h: float) -> int:
    """Pull over-stretched springs back to ``(1 + max_stretch) rest`` in place.

    Args:
        x, v: (n, 3) positions and velocities (modified in place).
        i, j, rest: springs to limit. inv_mass: (n,) inverse masses, 0 for pinned vertices.
        max_stretch: allowed relative stretch (0.1 = 10 %). h: sub-step [s].

    Returns:
        The number of springs over the limit before the first sweep.
    """
    if len(i) == 0:
        return 0
    n = len(x)
    limit = (1.0 + max_stretch) * rest
    w_i, w_j = inv_mass[i], inv_mass[j]
    w_sum = w_i + w_j
    movable = w_sum > 0.0
    count = np.bincount(i, minlength=n) + np.bincount(j, minlength=n)
    count = np.maximum(count, 1)[:, None]
    start = x.copy()
    first = 0
    for sweep in range(SWEEPS):
        d = x[i] - x[j]
        length = np.sqrt(np.einsum("ij,ij->i", d, d))
        over = movable & (length > limit)
        if sweep == 0:
            first = int(np.count_nonzero(over))
        if not over.any():
            break
        k = np.nonzero(over)[0]
        excess = ((length[k] - limit[k]) / np.maximum(length[k], 1e-12))[:, None] * d[k]
        share = excess / w_sum[k][:, None]
        corr = np.zeros((n, 3))
        for axis in range(3):
            corr[:, axis] -= np.bincount(i[k], weights=w_i[k] * share[:, axis], minlength=n)
            corr[:, axis] += np.bincount(j[k], weights=w_j[k] * share[:, axis], minlength=n)
        x += RELAXATION * corr / count
    v += (x - start) / h
    return first
