"""Unit quaternions [w, x, y, z] (Blender's order), vectorised over rows: (n, 4) arrays."""
from __future__ import annotations

import numpy as np

from ..transforms import cross


def multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products a b of (n, 4) (or (4,)) quaternions: the rotation b, then a."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]  # (views: no moveaxis call)
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def conjugate(q: np.ndarray) -> np.ndarray:
    """The inverse rotation of unit quaternions."""
    return np.asarray(q, dtype=np.float64) * np.array([1.0, -1.0, -1.0, -1.0])


def normalized(q: np.ndarray) -> np.ndarray:
    """Unit quaternions with w >= 0 (the same rotations, one sign)."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0.0, -q, q)


def to_matrix(q: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotation matrices of (n, 4) unit quaternions (column vectors: x' = R x)."""
    q = np.asarray(q, dtype=np.float64)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    r = np.empty((9,) + np.shape(w))  # entry by entry (contiguous writes), then rows
    r[0] = 1 - 2 * (y * y + z * z)
    r[1] = 2 * (x * y - z * w)
    r[2] = 2 * (x * z + y * w)
    r[3] = 2 * (x * y + z * w)
    r[4] = 1 - 2 * (x * x + z * z)
    r[5] = 2 * (y * z - x * w)
    r[6] = 2 * (x * z - y * w)
    r[7] = 2 * (y * z + x * w)
    r[8] = 1 - 2 * (x * x + y * y)
    return np.ascontiguousarray(r.reshape(9, -1).T).reshape(np.shape(w) + (3, 3))


def from_matrix(r: np.ndarray) -> np.ndarray:
    """(n, 4) unit quaternions (w >= 0) of (n, 3, 3) rotation matrices (Shepperd's method,
    branch chosen per row for accuracy)."""
    r = np.asarray(r, dtype=np.float64).reshape(-1, 3, 3)
    diag = np.stack([r[:, 0, 0], r[:, 1, 1], r[:, 2, 2]], axis=1)
    trace = diag.sum(axis=1)
    # 4 candidates (4 w^2, 4 x^2, 4 y^2, 4 z^2); use the largest for each row
    big = np.stack([1 + trace, 1 + 2 * diag[:, 0] - trace, 1 + 2 * diag[:, 1] - trace,
                    1 + 2 * diag[:, 2] - trace], axis=1)
    pick = np.argmax(big, axis=1)
    s = 2.0 * np.sqrt(np.maximum(big[np.arange(len(r)), pick], 1e-300))
    wx, wy, wz = r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]
    xy, xz, yz = r[:, 0, 1] + r[:, 1, 0], r[:, 0, 2] + r[:, 2, 0], r[:, 1, 2] + r[:, 2, 1]
    q = np.select([(pick == k)[:, None] for k in range(4)], [
        np.stack([s / 4, wx / s, wy / s, wz / s], 1),
        np.stack([wx / s, s / 4, xy / s, xz / s], 1),
        np.stack([wy / s, xy / s, s / 4, yz / s], 1),
        np.stack([wz / s, xz / s, yz / s, s / 4], 1)])
    return normalized(q)


def from_rotation_vector(theta: np.ndarray) -> np.ndarray:
    """exp of (n, 3) rotation vectors (axis * angle [rad]) as (n, 4) unit quaternions."""
    theta = np.asarray(theta, dtype=np.float64)
    angle = np.linalg.norm(theta, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(a/2)/a without dividing by zero: its series below 1e-4 rad
    k = np.where(angle > 1e-4, np.sin(half) / np.where(angle > 1e-4, angle, 1.0),
                 0.5 - angle * angle / 48.0)
    return np.concatenate([np.cos(half), k * theta], axis=-1)


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Vectors v (n, 3) rotated by unit quaternions q (n, 4) (or one of either)."""
    q = np.asarray(q, dtype=np.float64)
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * cross(u, v)
    return v + w * t + cross(u, t)
