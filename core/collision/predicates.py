"""Exact orientation predicates: the sign of 2D and 3D orientation determinants, batched.

Every exact test in the collision library (triangle-triangle, segment-triangle) is built only
from the *signs* of these determinants, so its answer is exact for the floating-point inputs
whenever these signs are.

Epsilon policy: there is none. Each determinant is first evaluated in double precision together
with a rigorous bound on its rounding error (Shewchuk's static filter, "Adaptive Precision
Floating-Point Arithmetic and Fast Robust Geometric Predicates", 1997). When the value exceeds the
bound its sign is certain; otherwise (inputs that are, or nearly are, coplanar / collinear) the
determinant is recomputed exactly with Python integers: every double is m * 2**e with a 53-bit
integer m, so scaling a row's coordinates to the smallest exponent makes them integers and the
determinant an exact integer polynomial. That fallback runs element-wise on object arrays; it is
slow per case but only ever sees the rare undecided rows.
"""
from __future__ import annotations

import numpy as np

from ..transforms import cross

_EPS = 2.0 ** -53
# Rounding-error bounds relative to the "permanent" (the determinant with every product made
# positive). Shewchuk's bounds are (3 + 16 eps) eps and (7 + 56 eps) eps; these round them up.
O2D_ERROR = 3.5e-16
O3D_ERROR = 8.0e-16
# Below this permanent, products may have underflowed and the bound no longer holds.
_TINY = 1e-250


def orient2d(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Exact sign of det[b - a, c - a] for 2D points.

    Args:
        a, b, c: (n, 2) points (finite).

    Returns:
        (n,) int8: +1 when a, b, c turn counter-clockwise, -1 clockwise, 0 collinear.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c = np.asarray(c, dtype=np.float64)
    ux, uy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    vx, vy = c[:, 0] - a[:, 0], c[:, 1] - a[:, 1]
    left, right = ux * vy, uy * vx
    det = left - right
    bound = O2D_ERROR * (np.abs(left) + np.abs(right))
    sign = np.sign(det).astype(np.int8)
    unsure = (np.abs(det) <= bound) | (bound < _TINY)
    if unsure.any():
        idx = np.nonzero(unsure)[0]
        sign[idx] = _exact_sign(np.concatenate([a[idx], b[idx], c[idx]], axis=1), _det2)
    return sign


def orient3d(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Exact sign of det[b - a, c - a, d - a] = ((b - a) x (c - a)) . (d - a).

    Args:
        a, b, c, d: (n, 3) points (finite).

    Returns:
        (n,) int8: +1 when d lies on the side of the plane through a, b, c that its normal
        (b - a) x (c - a) points to, -1 on the other side, 0 when the four points are coplanar.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c = np.asarray(c, dtype=np.float64)
    d = np.asarray(d, dtype=np.float64)
    u, v, w = b - a, c - a, d - a
    p1, p2 = v[:, 1] * w[:, 2], v[:, 2] * w[:, 1]
    q1, q2 = v[:, 2] * w[:, 0], v[:, 0] * w[:, 2]
    r1, r2 = v[:, 0] * w[:, 1], v[:, 1] * w[:, 0]
    det = u[:, 0] * (p1 - p2) + u[:, 1] * (q1 - q2) + u[:, 2] * (r1 - r2)
    perm = (np.abs(u[:, 0]) * (np.abs(p1) + np.abs(p2))
            + np.abs(u[:, 1]) * (np.abs(q1) + np.abs(q2))
            + np.abs(u[:, 2]) * (np.abs(r1) + np.abs(r2)))
    bound = O3D_ERROR * perm
    sign = np.sign(det).astype(np.int8)
    unsure = (np.abs(det) <= bound) | (perm < _TINY)
    if unsure.any():
        idx = np.nonzero(unsure)[0]
        rows = np.concatenate([a[idx], b[idx], c[idx], d[idx]], axis=1)
        sign[idx] = _exact_sign(rows, _det3)
    return sign


def orient3d_value(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Floating-point value of det[b - a, c - a, d - a] (n,), for interpolation after the exact
    sign has decided the topology."""
    u, v, w = b - a, c - a, d - a
    return np.einsum("ij,ij->i", u, cross(v, w))


# --- exact fallback ----------------------------------------------------------------------------

def _exact_integers(rows: np.ndarray) -> np.ndarray:
    """(m, k) doubles -> (m, k) object array of Python ints, each row scaled by one power of 2.

    Scaling a row by a positive power of two does not change any determinant's sign that is
    homogeneous in the row's coordinates, which all of ours are.
    """
    mant, expo = np.frexp(rows)
    ints = (mant * 2.0 ** 53).astype(np.int64)  # exact: |mant| < 1 has 53 significant bits
    expo = expo.astype(np.int64) - 53
    expo = np.where(ints == 0, np.iinfo(np.int64).max, expo)
    low = expo.min(axis=1, keepdims=True)
    low = np.where(low == np.iinfo(np.int64).max, 0, low)  # an all-zero row
    shift = np.where(ints == 0, 0, expo - low)
    return ints.astype(object) << shift.astype(object)


def _det2(x: np.ndarray):
    ax, ay, bx, by, cx, cy = (x[:, i] for i in range(6))
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


def _det3(x: np.ndarray):
    a, b, c, d = x[:, 0:3], x[:, 3:6], x[:, 6:9], x[:, 9:12]
    u0, u1, u2 = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1], b[:, 2] - a[:, 2]
    v0, v1, v2 = c[:, 0] - a[:, 0], c[:, 1] - a[:, 1], c[:, 2] - a[:, 2]
    w0, w1, w2 = d[:, 0] - a[:, 0], d[:, 1] - a[:, 1], d[:, 2] - a[:, 2]
    return u0 * (v1 * w2 - v2 * w1) + u1 * (v2 * w0 - v0 * w2) + u2 * (v0 * w1 - v1 * w0)


def _exact_sign(rows: np.ndarray, det) -> np.ndarray:
    value = det(_exact_integers(rows))
    return ((value > 0).astype(np.int8) - (value < 0).astype(np.int8)).astype(np.int8)
