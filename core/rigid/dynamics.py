"""Rigid-body kinematics and free motion: world inertia, velocities from momenta, orientation
integration with the angular momentum held (Witkin & Baraff: L is the state, w derived)."""
from __future__ import annotations

import numpy as np

from . import quaternion as quat


def world_tensor(q: np.ndarray, local: np.ndarray) -> np.ndarray:
    """R T R^T of (n, 3, 3) local tensors for bodies at orientations q (n, 4)."""
    r = quat.to_matrix(q)
    return (r @ local) @ np.ascontiguousarray(np.swapaxes(r, 1, 2))  # (contiguous: faster)


def _applied(r: np.ndarray, local: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R (T (R^T v)): a world tensor times vectors (n, 3) without forming the tensor (three
    matrix-vector products cost a third of two matrix products and one)."""
    return np.einsum("nij,nj->ni", r, np.einsum("nij,nj->ni", local,
                                                np.einsum("nji,nj->ni", r, v)))


def angular_velocity(q: np.ndarray, inv_inertia: np.ndarray, L: np.ndarray,
                     r: np.ndarray | None = None) -> np.ndarray:
    """w = I(t)^-1 L, (n, 3) [rad/s], with I(t)^-1 = R I_body^-1 R^T (r: R of q, if known)."""
    return _applied(quat.to_matrix(q) if r is None else r, inv_inertia, L)


def angular_momentum(q: np.ndarray, inertia: np.ndarray, w: np.ndarray,
                     r: np.ndarray | None = None) -> np.ndarray:
    """L = I(t) w, (n, 3) [kg m^2/s] (r: R of q, if known)."""
    return _applied(quat.to_matrix(q) if r is None else r, inertia, w)


def integrate_orientation(q: np.ndarray, inv_inertia: np.ndarray, L: np.ndarray,
                          h: float, r: np.ndarray | None = None) -> np.ndarray:
    """Orientations after h [s] of torque-free motion with angular momentum L (n, 3) held:
    the Lie-group midpoint rule (second order): w at the half step's orientation turns the
    whole step, q1 = exp(h w(q_half)) q0. Rotation about an intermediate axis then flips
    periodically (Dzhanibekov) instead of drifting in energy as explicit w-stepping does.
    r: R of q, if known."""
    w0 = angular_velocity(q, inv_inertia, L, r)
    half = quat.multiply(quat.from_rotation_vector(0.5 * h * w0), q)
    w_half = angular_velocity(half, inv_inertia, L)
    return quat.normalized(quat.multiply(quat.from_rotation_vector(h * w_half), q))
