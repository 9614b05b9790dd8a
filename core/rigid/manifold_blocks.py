"""A contact manifold's normal coupling and its pseudo-inverses: the whole manifold's block and
one for each subset of its points (what :mod:`.contact_solver` solves a manifold's normal
impulses with, together or with some points let go)."""
from __future__ import annotations

import numpy as np

from .contact_set import subset_width


def coupling(valid: np.ndarray, jn: np.ndarray, mn: np.ndarray) -> np.ndarray:
    """Per manifold, K_ij = J_i M^-1 J_j^T over its points' normal rows, empty slots as
    decoupled unit rows. Four coplanar points of a face leave K rank 3; the minimum-norm
    solution (its pseudo-inverse) then shares the load symmetrically, where point-by-point
    Gauss-Seidel would favour whichever point comes first (and set a stack swaying)."""
    return restricted(np.einsum("mij,mkj->mik", jn, mn), valid)


def pinv(k: np.ndarray) -> np.ndarray:
    """Pseudo-inverses of symmetric positive semi-definite matrices (g, S, S), eigenvalues
    below 1e-10 of the largest taken as zero (numpy's pinv, without its per-call overhead)."""
    value, vector = np.linalg.eigh(k)
    keep = value > 1e-10 * value[:, -1:]
    inverse = np.where(keep, 1.0 / np.where(keep, value, 1.0), 0.0)
    return np.einsum("gik,gk,gjk->gij", vector, inverse, vector)


def subset_masks(width: int) -> np.ndarray:
    """(2^width, width) bool: slot i is in subset c when bit i of c is set."""
    return (np.arange(1 << width)[:, None] >> np.arange(width)) & 1 == 1


_SUBSET_TABLES: dict = {}


def subset_table(width: int) -> tuple[np.ndarray, np.ndarray]:
    """The subsets of ``width`` slots (:func:`subset_masks`) and the order they are preferred
    in when several are complementary (C,) > 0: more points first, then the lower index."""
    table = _SUBSET_TABLES.get(width)
    if table is None:
        masks = subset_masks(width)
        table = _SUBSET_TABLES[width] = (masks, masks.sum(axis=1) * 64 - np.arange(len(masks))
                                         + 64.0)
    return table


def subset_blocks(k: np.ndarray, block: np.ndarray) -> np.ndarray:
    """(g, 2^W, W, W): the pseudo-inverse of each coupling (g, S, S) restricted to each
    subset of its first W = min(S, 4) slots (zero outside the subset), so that a manifold
    whose block solution would pull finds its complementary solution without a
    factorisation (:func:`.contact_solver._enumerated`). ``block`` (g, S, S): the pseudo-inverses of the
    whole couplings (the subset of all W slots when S = W). Subsets of up to three points are
    inverted in closed form; singular ones (collinear points) through :func:`pinv`."""
    g, w = len(k), subset_width(k.shape[1])
    masks = subset_masks(w)
    size = masks.sum(axis=1)
    out = np.zeros((g, len(masks), w, w))
    for n in range(1, w + 1):
        which = np.nonzero(size == n)[0]
        slots = np.array([np.nonzero(masks[c])[0] for c in which])  # (c, n)
        if n == k.shape[1]:
            inv = block[:, None]
        else:
            sub = k[:, slots[:, :, None], slots[:, None, :]]  # (g, c, n, n)
            inv = small_inverse(sub)
        out[:, which[:, None, None], slots[:, :, None], slots[:, None, :]] = inv
    return out


def small_inverse(k: np.ndarray) -> np.ndarray:
    """Pseudo-inverses of symmetric positive semi-definite matrices (..., n, n), n <= 4: the
    adjugate over the determinant for n <= 3 where the matrix is far from singular,
    :func:`pinv` otherwise."""
    n = k.shape[-1]
    shape = k.shape
    flat = k.reshape(-1, n, n)
    if n == 1:
        d = flat[:, 0, 0]
        return np.where(d > 0.0, 1.0 / np.where(d > 0.0, d, 1.0), 0.0).reshape(shape)
    if n == 2:
        a, b, d = flat[:, 0, 0], flat[:, 0, 1], flat[:, 1, 1]
        det = a * d - b * b
        adj = np.stack([d, -b, -b, a], axis=1).reshape(-1, 2, 2)
        scale = a * d
    elif n == 3:
        a, b, c = flat[:, 0, 0], flat[:, 0, 1], flat[:, 0, 2]
        d, e, f = flat[:, 1, 1], flat[:, 1, 2], flat[:, 2, 2]
        ca, cb, cc = d * f - e * e, c * e - b * f, b * e - c * d
        cd, ce, cf = a * f - c * c, b * c - a * e, a * d - b * b
        det = a * ca + b * cb + c * cc
        adj = np.stack([ca, cb, cc, cb, cd, ce, cc, ce, cf], axis=1).reshape(-1, 3, 3)
        scale = a * d * f
    else:
        return pinv(flat).reshape(shape)
    good = det > 1e-8 * np.maximum(scale, 1e-300)
    out = adj / np.where(good, det, 1.0)[:, None, None]
    bad = np.nonzero(~good)[0]
    if len(bad):
        out[bad] = pinv(flat[bad])
    return out.reshape(shape)


def restricted(k: np.ndarray, rows_: np.ndarray) -> np.ndarray:
    """K (g, S, S) with the rows and columns outside ``rows_`` (g, S) made unit rows."""
    pair = rows_[:, :, None] & rows_[:, None, :]
    eye = np.broadcast_to(np.eye(rows_.shape[1], dtype=bool), k.shape)
    return np.where(pair, k, np.where(eye, 1.0, 0.0))
