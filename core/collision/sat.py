"""OBB-OBB separating-axis test in the frame of box A, batched over pairs (Gottschalk 1996).

Two boxes are disjoint exactly when one of 15 axes separates their projections: the 3 face
normals of A, the 3 of B, and the 9 cross products of an edge direction of A with one of B, in
that order. Everything is expressed in A's frame: R[i, j] = a_i . b_j and T = A^T (c_B - c_A), so
A's axes are the coordinate axes and B's are R's columns.

The 6-axis variant (faces only) skips the 9 edge-edge axes: cheaper, and it can report
overlap for boxes that only an edge-edge axis separates (never the reverse), which a hierarchy
tolerates by descending further.

Rounding: near-parallel edges make a cross-product axis vanish and both sides of its test tiny;
:data:`PARALLEL_SLACK` is added to every |R[i, j]| so that rounding can never manufacture a
separation (boxes within ~1e-12 of their size count as touching).
"""
from __future__ import annotations

import numpy as np

PARALLEL_SLACK = 1e-12

# the 9 edge-edge axes a_i x b_j in the seed's order (i major), with the cyclic successors
_I = np.repeat(np.arange(3), 3)
_J = np.tile(np.arange(3), 3)
_I1, _I2 = (_I + 1) % 3, (_I + 2) % 3
_J1, _J2 = (_J + 1) % 3, (_J + 2) % 3


def obb_overlap(centre_a, axes_a, half_a, centre_b, axes_b, half_b, margin: float = 0.0,
                axis_count: int = 15) -> np.ndarray:
    """Whether boxes A and B come within ``margin`` of each other.

    Args:
        centre_a, centre_b: (n, 3) box centres [m].
        axes_a, axes_b: (n, 3, 3) unit axes as rows (row i = axis i).
        half_a, half_b: (n, 3) half-extents along the axes [m].
        margin: distance [m] by which both boxes count as grown.
        axis_count: 15 (exact) or 6 (face axes only; may report false overlaps).

    Returns:
        (n,) bool, True when no tested axis separates the boxes.
    """
    if axis_count not in (6, 15):
        raise ValueError(f"the OBB separating-axis test uses 15 or 6 axes (got {axis_count})")
    r = np.matmul(axes_a, axes_b.transpose(0, 2, 1))
    t = np.einsum("nik,nk->ni", axes_a, centre_b - centre_a)
    abs_r = np.abs(r) + PARALLEL_SLACK
    # 3 face axes of A: L = a_i
    sep = np.abs(t) > half_a + np.einsum("nij,nj->ni", abs_r, half_b) + margin
    hit = ~sep.any(axis=1)
    # 3 face axes of B: L = b_j
    tb = np.einsum("ni,nij->nj", t, r)
    sep = np.abs(tb) > np.einsum("ni,nij->nj", half_a, abs_r) + half_b + margin
    hit &= ~sep.any(axis=1)
    if axis_count == 6:
        return hit
    idx = np.nonzero(hit)[0]
    if len(idx):
        hit[idx] = _edge_axes_overlap(r[idx], abs_r[idx], t[idx], half_a[idx], half_b[idx],
                                      margin)
    return hit


def _edge_axes_overlap(r, abs_r, t, ha, hb, margin) -> np.ndarray:
    """No edge-edge axis a_i x b_j separates (pairs that survived the face axes)."""
    r, abs_r = r.reshape(-1, 9), abs_r.reshape(-1, 9)  # flat (i, j) -> 3 i + j
    ra = ha[:, _I1] * abs_r[:, 3 * _I2 + _J] + ha[:, _I2] * abs_r[:, 3 * _I1 + _J]
    rb = hb[:, _J1] * abs_r[:, 3 * _I + _J2] + hb[:, _J2] * abs_r[:, 3 * _I + _J1]
    dist = np.abs(t[:, _I2] * r[:, 3 * _I1 + _J] - t[:, _I1] * r[:, 3 * _I2 + _J])
    length = np.sqrt(np.maximum(1.0 - r[:, 3 * _I + _J] ** 2, 0.0))  # |a_i x b_j|
    return ~np.any(dist > ra + rb + margin * length, axis=1)
