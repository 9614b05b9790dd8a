"""Spring-mesh forces with the Jacobian products an implicit integrator needs.

Each force object has ``apply(p, f_out)`` (the particle force interface of
:mod:`physanim.core.particles.forces`) and ``linearize(p)``, which returns its Jacobian at that
state as blocks; ``.operator(cx, cv)`` of those blocks is the matrix-free product
``u -> (cx df/dx + cv df/dv) u`` an implicit solve applies many times — vectorised, accumulated
with ``np.bincount`` (no per-spring Python loop).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..particles.forces import ParticleView
from .topology import dihedral_angles


def flat_index(index: np.ndarray) -> np.ndarray:
    """Indices of the x, y, z components of rows ``index`` in a flattened (n, 3) array."""
    return (np.asarray(index)[:, None] * 3 + np.arange(3)).ravel()


def scatter_add(out: np.ndarray, index: np.ndarray, values: np.ndarray,
                flat: np.ndarray | None = None) -> None:
    """out[index] += values for (m, 3) values, repeated indices summed (one flat bincount).
    ``flat`` = flat_index(index), precomputed by callers that scatter often."""
    if flat is None:
        flat = flat_index(index)
    out += np.bincount(flat, weights=values.ravel(), minlength=out.size).reshape(out.shape)


class PairOperator:
    """u -> sum over pairs of C (u_i - u_j) added to i and subtracted from j; C (s, 3, 3)."""

    def __init__(self, i: np.ndarray, j: np.ndarray, blocks: np.ndarray):
        self.i, self.j, self.blocks = i, j, blocks
        self.index = np.concatenate([i, j])
        self.flat = flat_index(self.index)

    def __call__(self, u: np.ndarray, out: np.ndarray) -> None:
        d = np.take(u, self.i, axis=0) - np.take(u, self.j, axis=0)  # take: faster than u[i]
        df = np.einsum("sab,sb->sa", self.blocks, d)
        scatter_add(out, self.index, np.concatenate([df, -df]), self.flat)


class HingeOperator:
    """u -> -c g (g . u) per hinge (Gauss-Newton bending), g (h, 4, 3), c scalar."""

    def __init__(self, hinge: np.ndarray, grad: np.ndarray, coefficient: float):
        self.hinge, self.grad, self.c = hinge, grad, coefficient
        self.index = hinge.ravel()  # (h, 4) row-major: matches f.reshape(-1, 3) below
        self.flat = flat_index(self.index)

    def __call__(self, u: np.ndarray, out: np.ndarray) -> None:
        w = self.c * np.einsum("hkc,hkc->h", self.grad, np.take(u, self.hinge, axis=0))
        f = -w[:, None, None] * self.grad  # (h, 4, 3)
        scatter_add(out, self.index, f.reshape(-1, 3), self.flat)


class VertexOperator:
    """u -> C_v u_v for per-vertex blocks C (s, 3, 3) at vertices ``index``."""

    def __init__(self, index: np.ndarray, blocks: np.ndarray):
        self.index, self.blocks = index, blocks
        self.flat = flat_index(index)

    def __call__(self, u: np.ndarray, out: np.ndarray) -> None:
        scatter_add(out, self.index,
                    np.einsum("sab,sb->sa", self.blocks, np.take(u, self.index, axis=0)), self.flat)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


@dataclass(frozen=True)
class SpringSet:
    """Damped springs between vertex pairs, Witkin & Baraff's formula:

    f_i = -[ks (|l| - r) + kd (l_dot . l)/|l|] l/|l|,  l = x_i - x_j,  f_j = -f_i.

    Args: i, j: (s,) vertex indices. rest: (s,) r [m]. stiffness, damping: (s,) ks [N/m],
    kd [N s/m] (per spring, so one set holds every family with its own constants).
    """

    i: np.ndarray
    j: np.ndarray
    rest: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray

    def _geometry(self, p: ParticleView):
        l = p.x[self.i] - p.x[self.j]
        length = np.sqrt(_dot(l, l))
        safe = np.where(length > 1e-12, length, 1.0)
        return l / safe[:, None], length, safe

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        if len(self.i) == 0:
            return
        u, length, _ = self._geometry(p)
        rate = _dot(p.v[self.i] - p.v[self.j], u)
        f = -(self.stiffness * (length - self.rest) + self.damping * rate)[:, None] * u
        scatter_add(f_out, self.i, f)
        scatter_add(f_out, self.j, -f)

    def linearize(self, p: ParticleView) -> "LinearizedPairs":
        """Jacobian blocks at this state. The transverse stiffness (1 - r/|l|) is clamped at 0
        so a compressed spring never makes the implicit system indefinite (Choi & Ko)."""
        u, _, safe = self._geometry(p)
        uu = u[:, :, None] * u[:, None, :]
        transverse = np.maximum(0.0, 1.0 - self.rest / safe)[:, None, None]
        kx = -self.stiffness[:, None, None] * (uu + transverse * (np.eye(3) - uu))
        kv = -self.damping[:, None, None] * uu
        return LinearizedPairs(self.i, self.j, kx, kv)

    def max_rate(self, mass: np.ndarray) -> float:
        """Upper bound of the highest angular frequency [1/s] of the spring network: by
        Gershgorin, omega^2 <= max over vertices of 2 (sum of incident ks) / m."""
        if len(self.i) == 0:
            return 0.0
        n = len(mass)
        incident = (np.bincount(self.i, weights=self.stiffness, minlength=n)
                    + np.bincount(self.j, weights=self.stiffness, minlength=n))
        return float(np.sqrt(np.max(2.0 * incident / mass)))


@dataclass(frozen=True)
class LinearizedPairs:
    """df/dx and df/dv of pair forces as (s, 3, 3) blocks B acting on x_i - x_j:
    out_i += B (u_i - u_j), out_j -= B (u_i - u_j)."""

    i: np.ndarray
    j: np.ndarray
    kx: np.ndarray
    kv: np.ndarray

    def operator(self, cx: float, cv: float) -> PairOperator:
        return PairOperator(self.i, self.j, cx * self.kx + cv * self.kv)

    def add_diagonal(self, cx: float, cv: float, out: np.ndarray) -> None:
        """out (n, 3, 3) += the operator's diagonal blocks (C at both ends of every pair)."""
        c = (cx * self.kx + cv * self.kv).reshape(-1, 9)
        n = len(out)
        flat = out.reshape(n, 9)
        for k in range(9):
            flat[:, k] += np.bincount(self.i, weights=c[:, k], minlength=n)
            flat[:, k] += np.bincount(self.j, weights=c[:, k], minlength=n)


@dataclass(frozen=True)
class LinearizedHinges:
    """Gauss-Newton bending Jacobian: df/dx u = -k g (g . u), df/dv u = -kd g (g . u), with g
    the dihedral gradients (h, 4, 3) — symmetric negative semi-definite, as CG needs."""

    hinge: np.ndarray
    grad: np.ndarray
    stiffness: float
    damping: float

    def operator(self, cx: float, cv: float) -> HingeOperator:
        return HingeOperator(self.hinge, self.grad, cx * self.stiffness + cv * self.damping)

    def add_diagonal(self, cx: float, cv: float, out: np.ndarray) -> None:
        """out (n, 3, 3) += -c g_a g_a^T at each hinge vertex a."""
        c = cx * self.stiffness + cv * self.damping
        g = self.grad.reshape(-1, 3)
        blocks = (-c * g[:, :, None] * g[:, None, :]).reshape(-1, 9)
        index = self.hinge.ravel()
        n = len(out)
        flat = out.reshape(n, 9)
        for k in range(9):
            flat[:, k] += np.bincount(index, weights=blocks[:, k], minlength=n)


def dihedral_gradients(x: np.ndarray, hinge: np.ndarray) -> np.ndarray:
    """d(theta)/dx of every hinge's dihedral angle: (h, 4, 3) for (e0, e1, w0, w1)."""
    x0, x1, x2, x3 = (x[hinge[:, k]] for k in range(4))
    e = x1 - x0
    length = np.sqrt(_dot(e, e))
    safe = np.where(length > 1e-12, length, 1.0)
    n1 = np.cross(x1 - x0, x2 - x0)
    n2 = np.cross(x3 - x0, x1 - x0)
    a1 = n1 / np.maximum(_dot(n1, n1), 1e-24)[:, None]
    a2 = n2 / np.maximum(_dot(n2, n2), 1e-24)[:, None]
    g2 = -safe[:, None] * a1
    g3 = -safe[:, None] * a2
    g0 = -(_dot(x2 - x1, e) / safe)[:, None] * a1 - (_dot(x3 - x1, e) / safe)[:, None] * a2
    g1 = (_dot(x2 - x0, e) / safe)[:, None] * a1 + (_dot(x3 - x0, e) / safe)[:, None] * a2
    return np.stack([g0, g1, g2, g3], axis=1)


@dataclass(frozen=True)
class AngularSprings:
    """Angular spring-dampers on hinges: the torque -[k (theta - theta0) + kd theta_dot] about
    the shared edge, applied as forces along d(theta)/dx (they sum to zero force and zero torque).

    Args: hinge: (h, 4) vertex indices (e0, e1, w0, w1). rest: (h,) theta0 [rad].
    stiffness: k [N m/rad]. damping: kd [N m s/rad].
    """

    hinge: np.ndarray
    rest: np.ndarray
    stiffness: float
    damping: float

    def _forces(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        grad = dihedral_gradients(x, self.hinge)
        theta = dihedral_angles(x, self.hinge)
        # wrap the difference so a hinge folded past pi still turns back the short way
        delta = np.angle(np.exp(1j * (theta - self.rest)))
        rate = np.einsum("hkc,hkc->h", grad, v[self.hinge])
        torque = self.stiffness * delta + self.damping * rate
        return -torque[:, None, None] * grad

    def _scatter(self, f: np.ndarray, out: np.ndarray) -> None:
        for k in range(4):
            scatter_add(out, self.hinge[:, k], f[:, k])

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        if len(self.hinge):
            self._scatter(self._forces(p.x, p.v), f_out)

    def linearize(self, p: ParticleView) -> LinearizedHinges:
        return LinearizedHinges(self.hinge, dihedral_gradients(p.x, self.hinge), self.stiffness,
                                self.damping)


@dataclass(frozen=True)
class AnchorSprings:
    """Virtual springs from vertices to moving anchor points (pins, attachments, keep-away).

    f = -[ks (|l| - r) + kd (l_dot . l)/|l|] l/|l| with l = x - a(t); for r = 0 this is the
    linear f = -ks (x - a) - kd (v - a_dot) (zero-rest-length, direction-free).

    Args: index: (s,) vertex indices. anchor0, anchor1: (s, 3) anchor positions at the start and
    end of the frame interval (linear in between). t0, duration: interval [s]. rest: (s,) [m].
    stiffness, damping: (s,) per spring (a vertex-group weight scales them).
    """

    index: np.ndarray
    anchor0: np.ndarray
    anchor1: np.ndarray
    t0: float
    duration: float
    rest: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray

    def anchor(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        s = np.clip((t - self.t0) / self.duration, 0.0, 1.0)
        velocity = (self.anchor1 - self.anchor0) / self.duration
        return self.anchor0 + s * (self.anchor1 - self.anchor0), velocity

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        if len(self.index) == 0:
            return
        a, va = self.anchor(p.t)
        l = p.x[self.index] - a
        ldot = p.v[self.index] - va
        zero = self.rest == 0.0
        length = np.sqrt(_dot(l, l))
        safe = np.where(length > 1e-12, length, 1.0)
        u = l / safe[:, None]
        radial = -(self.stiffness * (length - self.rest) + self.damping * _dot(ldot, u))[:, None] * u
        linear = -self.stiffness[:, None] * l - self.damping[:, None] * ldot
        scatter_add(f_out, self.index, np.where(zero[:, None], linear, radial))

    def linearize(self, p: ParticleView) -> "LinearizedVertices":
        a, _ = self.anchor(p.t)
        l = p.x[self.index] - a
        length = np.sqrt(_dot(l, l))
        safe = np.where(length > 1e-12, length, 1.0)
        u = l / safe[:, None]
        uu = u[:, :, None] * u[:, None, :]
        eye = np.broadcast_to(np.eye(3), uu.shape)
        zero = (self.rest == 0.0)[:, None, None]
        transverse = np.maximum(0.0, 1.0 - self.rest / safe)[:, None, None]
        kx = -self.stiffness[:, None, None] * np.where(zero, eye, uu + transverse * (eye - uu))
        kv = -self.damping[:, None, None] * np.where(zero, eye, uu)
        return LinearizedVertices(self.index, kx, kv)


@dataclass(frozen=True)
class LinearizedVertices:
    """df/dx and df/dv as per-vertex (s, 3, 3) blocks."""

    index: np.ndarray
    kx: np.ndarray
    kv: np.ndarray

    def operator(self, cx: float, cv: float) -> VertexOperator:
        return VertexOperator(self.index, cx * self.kx + cv * self.kv)

    def add_diagonal(self, cx: float, cv: float, out: np.ndarray) -> None:
        c = (cx * self.kx + cv * self.kv).reshape(-1, 9)
        n = len(out)
        flat = out.reshape(n, 9)
        for k in range(9):
            flat[:, k] += np.bincount(self.index, weights=c[:, k], minlength=n)


@dataclass(frozen=True)
class LinearDrag:
    """Viscous air drag f = -k m v (k [1/s] per unit mass, so heavy and light cloth slow alike)."""

    k: float

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        if self.k:
            f_out -= (self.k * p.mass)[:, None] * p.v

    def linearize(self, p: ParticleView) -> LinearizedVertices:
        n = len(p.mass)
        kv = -(self.k * p.mass)[:, None, None] * np.eye(3)
        return LinearizedVertices(np.arange(n), np.zeros((n, 3, 3)), kv)
