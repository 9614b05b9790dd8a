"""Rigid-ish affine transforms: interpolation between two samples and point/normal mapping.

Transforms are 4x4 affine matrices (column vectors: ``x_world = M @ [x_local, 1]``) made of
translation, rotation and per-axis scale, as an object's world matrix is. Interpolating them
component-wise would shrink a rotating object mid-step, so :func:`interpolate` splits each matrix
into translation, rotation (quaternion, slerped) and scale (lerped).
"""
from __future__ import annotations

import math

import numpy as np


def decompose(m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split a 4x4 affine matrix into translation (3,), quaternion (4,) [w,x,y,z] and scale (3,)."""
    m = np.asarray(m, dtype=np.float64)
    linear = m[:3, :3]
    scale = np.linalg.norm(linear, axis=0)
    safe = np.where(scale > 0.0, scale, 1.0)
    rot = linear / safe
    if np.linalg.det(rot) < 0.0:  # mirrored: fold the reflection into the scale
        scale[0] = -scale[0]
        rot[:, 0] = -rot[:, 0]
    return m[:3, 3].copy(), matrix_to_quaternion(rot), scale


def compose(translation: np.ndarray, quat: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Inverse of :func:`decompose`."""
    m = np.eye(4)
    m[:3, :3] = quaternion_to_matrix(quat) * np.asarray(scale, dtype=np.float64)
    m[:3, 3] = translation
    return m


def matrix_to_quaternion(r: np.ndarray) -> np.ndarray:
    """Unit quaternion [w, x, y, z] of a 3x3 rotation matrix (Shepperd's method)."""
    t = np.trace(r)
    if t > 0.0:
        s = np.sqrt(t + 1.0) * 2.0
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2.0
        q = [(r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s]
    elif r[1, 1] > r[2, 2]:
        s = np.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2.0
        q = [(r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s]
    else:
        s = np.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2.0
        q = [(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    return q / np.linalg.norm(q)


def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    """3x3 rotation matrix of a quaternion [w, x, y, z] (normalised first)."""
    w, x, y, z = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def rotation_vector_matrix(theta: np.ndarray) -> np.ndarray:
    """(3, 3) rotation by the rotation vector ``theta`` (axis times angle [rad])."""
    angle = float(np.linalg.norm(theta))
    if angle < 1e-15:
        return np.eye(3)
    half = 0.5 * angle
    return quaternion_to_matrix(np.array([math.cos(half), *(math.sin(half) / angle * theta)]))


def matrix_rotation_vector(r: np.ndarray) -> np.ndarray:
    """(3,) the rotation vector (axis times angle [rad], angle in [0, pi]) of the rotation
    matrix ``r`` (3, 3): the inverse of :func:`rotation_vector_matrix`."""
    q = matrix_to_quaternion(r)
    q = q if q[0] >= 0.0 else -q
    sine = float(np.linalg.norm(q[1:]))
    if sine < 1e-15:
        return 2.0 * q[1:]
    return q[1:] * (2.0 * math.atan2(sine, q[0]) / sine)


def slerp(q0: np.ndarray, q1: np.ndarray, s: np.ndarray | float) -> np.ndarray:
    """Spherical interpolation of unit quaternions along the shorter arc.

    ``q0``/``q1`` are (4,) or (..., 4) (pairwise); ``s`` broadcasts against their leading shape.
    """
    q0 = np.asarray(q0, dtype=np.float64)
    q1 = np.asarray(q1, dtype=np.float64)
    d = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(d < 0.0, -q1, q1)
    d = np.abs(d)
    s = np.asarray(s, dtype=np.float64)[..., None]
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    sin_t = np.sin(theta)
    near = d > 0.9995  # nearly parallel: lerp is exact to rounding and avoids 0/0
    safe = np.where(near, 1.0, sin_t)
    w0 = np.where(near, 1.0 - s, np.sin((1.0 - s) * theta) / safe)
    w1 = np.where(near, s, np.sin(s * theta) / safe)
    q = w0 * q0 + w1 * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


class TransformPath:
    """A transform moving through key samples over an interval s = 0..1, evaluated at many s.

    Between keys, translation and scale are interpolated linearly and rotation by slerp, so a
    rotating object keeps its shape. More keys (sub-frame samples) follow curved motion — an
    arm's swing — more closely than the two ends of a frame can.

    Args:
        m0: (4, 4) world matrix at s = 0.
        m1: (4, 4) world matrix at s = 1.
        samples: optional (k + 1, 4, 4) matrices at s = 0, 1/k, ..., 1 (overrides m0/m1).
    """

    def __init__(self, m0: np.ndarray, m1: np.ndarray, samples: np.ndarray | None = None):
        if samples is None:
            samples = np.stack([np.asarray(m0, np.float64), np.asarray(m1, np.float64)])
        self.samples = np.asarray(samples, dtype=np.float64)
        if self.samples.ndim != 3 or self.samples.shape[1:] != (4, 4) or len(self.samples) < 2:
            raise ValueError(f"transform samples must be (k + 1, 4, 4) with k >= 1 "
                             f"(got {self.samples.shape})")
        self.m0 = self.samples[0]
        self.m1 = self.samples[-1]
        self.static = bool(np.all(self.samples == self.samples[0]))
        parts = [decompose(m) for m in self.samples]
        self._t = np.array([p[0] for p in parts])
        q = np.array([p[1] for p in parts])
        for k in range(1, len(q)):  # keep consecutive keys on the same hemisphere
            if np.dot(q[k - 1], q[k]) < 0.0:
                q[k] = -q[k]
        self._q = q
        self._s = np.array([p[2] for p in parts])

    def matrices(self, s: np.ndarray | float) -> np.ndarray:
        """(..., 4, 4) matrices at interpolation parameters ``s`` in [0, 1]."""
        s = np.asarray(s, dtype=np.float64)
        if self.static:
            return np.broadcast_to(self.m0, s.shape + (4, 4))
        keys = len(self.samples) - 1
        x = np.clip(s, 0.0, 1.0) * keys
        j = np.minimum(np.floor(x), keys - 1).astype(np.int64)
        w = x - j
        q = slerp(self._q[j], self._q[j + 1], w)
        w, x, y, z = np.moveaxis(q, -1, 0)
        rot = np.stack([
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ], -2)
        wv = (np.clip(s, 0.0, 1.0) * keys - j)[..., None]
        scale = self._s[j] + wv * (self._s[j + 1] - self._s[j])
        trans = self._t[j] + wv * (self._t[j + 1] - self._t[j])
        out = np.zeros(s.shape + (4, 4))
        out[..., :3, :3] = rot * scale[..., None, :]
        out[..., :3, 3] = trans
        out[..., 3, 3] = 1.0
        return out

    def points(self, local: np.ndarray, s: np.ndarray | float) -> np.ndarray:
        """World positions (n, 3) of local points (n, 3) at per-point parameters ``s`` (n,)."""
        local = np.asarray(local, dtype=np.float64)
        if self.static:
            return local @ self.m0[:3, :3].T + self.m0[:3, 3]
        m = self.matrices(np.broadcast_to(np.asarray(s, dtype=np.float64), local.shape[:1]))
        return np.einsum("nij,nj->ni", m[:, :3, :3], local) + m[:, :3, 3]

    def point_velocities(self, local: np.ndarray, s: np.ndarray | float, duration: float,
                         local_velocity: np.ndarray | None = None) -> np.ndarray:
        """d/dt of the world positions of local points at ``s`` [m/s] (central difference in s).

        Args:
            local: (n, 3) local positions.
            s: (n,) or scalar parameters in [0, 1].
            duration: length of the interval s = 0..1 [s].
            local_velocity: (n, 3) velocity of the points in local space (deforming meshes) [m/s].
        """
        local = np.asarray(local, dtype=np.float64)
        s = np.broadcast_to(np.asarray(s, dtype=np.float64), local.shape[:1])
        if self.static:
            vel = np.zeros_like(local)
        else:
            ds = 1e-4
            lo = np.clip(s - ds, 0.0, 1.0)
            hi = np.clip(s + ds, 0.0, 1.0)
            span = (hi - lo)[:, None] * duration
            vel = (self.points(local, hi) - self.points(local, lo)) / span
        if local_velocity is not None:
            m = self.matrices(s)
            vel = vel + np.einsum("nij,nj->ni", m[:, :3, :3], local_velocity)
        return vel


# --- small dense linear algebra without BLAS ---------------------------------------------------
# numpy sends (n, 3) @ (3, 3) and 3x3/4x4 inverses to (multi-threaded) BLAS/LAPACK, whose call
# overhead dwarfs the arithmetic here; these closed forms are plain vectorised element-wise math.

def dot_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot products of two (n, 3) arrays: (n,)."""
    return np.einsum("ij,ij->i", a, b)


def rows_at(a: np.ndarray, index: np.ndarray) -> np.ndarray:
    """``a[index]`` for sorted, unique row indices (``np.nonzero``'s): ``a`` itself (no copy)
    when they are every row — a settled pile rests whole on its ground, and gathering all of
    it costs more than the arithmetic done on it. Read-only use: the result may be ``a``."""
    return a if len(index) == len(a) else take(a, index)


def take(a: np.ndarray, index: np.ndarray) -> np.ndarray:
    """``a[index]`` for an integer index array: the rows of ``a`` (any trailing shape). The same
    result as fancy indexing, several times faster for rows of more than one value (numpy
    1.26: 3 x for (n, 3) rows)."""
    return np.take(a, index, axis=0)


def scale_rows(a: np.ndarray, s: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``a * s[:, None]`` for (n, k) ``a`` and (n,) ``s``, column by column (into ``out``, which
    may be ``a``): numpy 1.26 runs that broadcast row by row, 5-10 x slower than k passes over
    the columns (4,096 x 3: 66 us against 12 us). The same values."""
    return _by_columns(np.multiply, a, s, out)


def divide_rows(a: np.ndarray, s: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``a / s[:, None]`` as :func:`scale_rows` does its product. The same values."""
    return _by_columns(np.divide, a, s, out)


def _by_columns(op, a: np.ndarray, s: np.ndarray, out: np.ndarray | None) -> np.ndarray:
    if out is None:
        out = np.empty(a.shape, np.result_type(a, s))
    for k in range(a.shape[1]):
        op(a[:, k], s, out=out[:, k])
    return out


def where_rows(cond: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.where(cond[:, None], a, b)`` for (n,) ``cond`` and (n, k) or (k,) ``a``, ``b``, by
    columns (the same values; the (n, 1) condition is broadcast row by row by numpy)."""
    a, b = np.asarray(a), np.asarray(b)
    k = a.shape[-1] if a.ndim else b.shape[-1]
    out = np.empty((len(cond), k), np.result_type(a, b))
    for j in range(k):
        out[:, j] = np.where(cond, a[..., j], b[..., j])
    return out


def row_indices(rows) -> np.ndarray:
    """Row indices for :func:`take` from ``rows``: indices, or a boolean mask."""
    rows = np.asarray(rows)
    return np.nonzero(rows)[0] if rows.dtype == bool else rows


# Reductions across a few narrow columns: numpy 1.26 runs ``a.min(axis=0)``, ``a.max(axis=1)``,
# ``m.any(axis=1)`` and the like element by element for (n, 3) arrays — 10 to 20 x slower than
# one reduction or one element-wise pass per column (4,096 rows: 124 us against 8 us). The
# results are the same values (min, max, any and all are exact).

def column_min(a: np.ndarray) -> np.ndarray:
    """(k,) the least value of each column of (n, k) ``a`` (n >= 1): ``a.min(axis=0)``."""
    return np.array([a[:, c].min() for c in range(a.shape[1])], dtype=a.dtype)


def column_max(a: np.ndarray) -> np.ndarray:
    """(k,) the greatest value of each column of (n, k) ``a`` (n >= 1): ``a.max(axis=0)``."""
    return np.array([a[:, c].max() for c in range(a.shape[1])], dtype=a.dtype)


def row_max(a: np.ndarray) -> np.ndarray:
    """(n,) the greatest value of each row of (n, k) ``a`` (k >= 1): ``a.max(axis=1)``."""
    out = a[:, 0].copy()
    for c in range(1, a.shape[1]):
        np.maximum(out, a[:, c], out=out)
    return out


def row_any(m: np.ndarray) -> np.ndarray:
    """(n,) whether any value of each row of (n, k) bool ``m`` is set: ``m.any(axis=1)``."""
    out = np.zeros(len(m), bool)
    for c in range(m.shape[1]):
        out |= m[:, c]
    return out


def row_all(m: np.ndarray) -> np.ndarray:
    """(n,) whether every value of each row of (n, k) bool ``m`` is set: ``m.all(axis=1)``."""
    out = np.ones(len(m), bool)
    for c in range(m.shape[1]):
        out &= m[:, c]
    return out


def norm_rows(a: np.ndarray) -> np.ndarray:
    """Euclidean norm of each row of (n, k) ``a``."""
    return np.sqrt(np.einsum("ij,ij->i", a, a))


def cross(u, v, out: np.ndarray | None = None) -> np.ndarray:
    """u x v of 3-vectors over the last axis, broadcast as ``np.cross`` and with the same values
    (the same products and differences, in the same order), without its fixed cost (axis moves
    and dtype copies: most of the time for a few hundred rows); into ``out`` when given. Other
    shapes (2-vectors) go to ``np.cross``."""
    u, v = np.asarray(u), np.asarray(v)
    if u.shape[-1:] != (3,) or v.shape[-1:] != (3,):
        return np.cross(u, v)
    if out is None:
        out = np.empty(np.broadcast_shapes(u.shape, v.shape), np.promote_types(u.dtype, v.dtype))
    u0, u1, u2 = u[..., 0], u[..., 1], u[..., 2]
    v0, v1, v2 = v[..., 0], v[..., 1], v[..., 2]
    np.subtract(u1 * v2, u2 * v1, out=out[..., 0])
    np.subtract(u2 * v0, u0 * v2, out=out[..., 1])
    np.subtract(u0 * v1, u1 * v0, out=out[..., 2])
    return out


def tangents(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (k, 3) completing each unit normal (k, 3) to an orthonormal basis."""
    helper = np.where((np.abs(n[:, 0]) < 0.57)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    t1 = cross(n, helper)
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    return t1, cross(n, t1)


def inverse3(a: np.ndarray) -> np.ndarray:
    """Inverse of (..., 3, 3) matrices by the adjugate formula."""
    a = np.asarray(a, dtype=np.float64)
    c00 = a[..., 1, 1] * a[..., 2, 2] - a[..., 1, 2] * a[..., 2, 1]
    c01 = a[..., 1, 2] * a[..., 2, 0] - a[..., 1, 0] * a[..., 2, 2]
    c02 = a[..., 1, 0] * a[..., 2, 1] - a[..., 1, 1] * a[..., 2, 0]
    det = a[..., 0, 0] * c00 + a[..., 0, 1] * c01 + a[..., 0, 2] * c02
    adj = np.empty_like(a)
    adj[..., 0, 0] = c00
    adj[..., 1, 0] = c01
    adj[..., 2, 0] = c02
    adj[..., 0, 1] = a[..., 0, 2] * a[..., 2, 1] - a[..., 0, 1] * a[..., 2, 2]
    adj[..., 1, 1] = a[..., 0, 0] * a[..., 2, 2] - a[..., 0, 2] * a[..., 2, 0]
    adj[..., 2, 1] = a[..., 0, 1] * a[..., 2, 0] - a[..., 0, 0] * a[..., 2, 1]
    adj[..., 0, 2] = a[..., 0, 1] * a[..., 1, 2] - a[..., 0, 2] * a[..., 1, 1]
    adj[..., 1, 2] = a[..., 0, 2] * a[..., 1, 0] - a[..., 0, 0] * a[..., 1, 2]
    adj[..., 2, 2] = a[..., 0, 0] * a[..., 1, 1] - a[..., 0, 1] * a[..., 1, 0]
    return adj / det[..., None, None]


def inverse_affine(m: np.ndarray) -> np.ndarray:
    """Inverse of (..., 4, 4) affine matrices: [A t; 0 1]^-1 = [A^-1  -A^-1 t; 0 1]."""
    m = np.asarray(m, dtype=np.float64)
    out = np.zeros_like(m)
    inv = inverse3(m[..., :3, :3])
    out[..., :3, :3] = inv
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", inv, m[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def transform_points(m: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Points (n, 3) mapped by one (4, 4) affine matrix or per-point (n, 4, 4) matrices."""
    if m.ndim == 2:  # x @ A^T sums x0 a0 + x1 a1 + x2 a2 in that order, in one pass
        if len(x) == 1:  # as a row of many: BLAS rounds one row (gemv) unlike several (gemm)
            return (np.repeat(x, 2, axis=0) @ m[:3, :3].T + m[:3, 3])[:1]
        out = x @ m[:3, :3].T
        for j in range(3):  # the translation by columns: numpy adds a (3,) row by row
            out[:, j] += m[j, 3]
        return out
    return np.einsum("nij,nj->ni", m[:, :3, :3], x) + m[:, :3, 3]


def transform_vectors(a: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Vectors (n, 3) mapped by one (3, 3) matrix or per-vector (n, 3, 3) matrices."""
    if a.ndim == 2:  # v0 a_j0 + v1 a_j1 + v2 a_j2 per output column j, in that order: the
        # values of the (n, 1) x (3,) broadcasts, which numpy runs row by row (10-15 x slower)
        v = np.asarray(v)
        out = np.empty((len(v), 3), np.result_type(a, v))
        c0, c1, c2 = v[:, 0], v[:, 1], v[:, 2]
        for j in range(3):
            col = np.multiply(c0, a[j, 0], out=out[:, j])
            col += c1 * a[j, 1]
            col += c2 * a[j, 2]
        return out
    return np.einsum("nij,nj->ni", a, v)
