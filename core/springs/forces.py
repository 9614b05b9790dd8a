"""Spring-mesh forces with the Jacobians an implicit integrator needs.

Each force object has ``apply(p, f_out)`` (the particle force interface of
:mod:`physanim.core.forces`) and ``linearize(p)``, which returns its Jacobian at that
state as 3 x 3 blocks: ``clique`` names the vertices it couples (None: per-vertex blocks only),
``add_to(builder, cx, cv)`` puts cx df/dx + cv df/dv into an assembled block-sparse matrix
(:mod:`physanim.core.springs.sparse`) and ``product(cx, cv, u, out)`` applies it once
matrix-free — vectorised, no per-spring Python loop.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..forces import ParticleView
from . import topology


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

    def __post_init__(self):
        # (s, 2): one fixed array naming the pairs, so a solver's block pattern is built once
        object.__setattr__(self, "pairs", np.stack([np.asarray(self.i, np.int64),
                                                    np.asarray(self.j, np.int64)], axis=1))
        object.__setattr__(self, "_flat", flat_index(np.concatenate([self.i, self.j])))

    def _geometry(self, p: ParticleView):
        l = np.take(p.x, self.i, axis=0, mode="clip") - np.take(p.x, self.j, axis=0, mode="clip")
        length = np.sqrt(_dot(l, l))
        safe = np.where(length > 1e-12, length, 1.0)
        return l / safe[:, None], length, safe

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        if len(self.i) == 0:
            return
        u, length, _ = self._geometry(p)
        rate = _dot(p.v[self.i] - p.v[self.j], u)
        f = -(self.stiffness * (length - self.rest) + self.damping * rate)[:, None] * u
        scatter_add(f_out, None, np.concatenate([f, -f]), self._flat)

    def linearize(self, p: ParticleView) -> LinearizedPairs:
        """Jacobian blocks at this state. The transverse stiffness (1 - r/|l|) is clamped at 0
        so a compressed spring never makes the implicit system indefinite (Choi & Ko)."""
        u, _, safe = self._geometry(p)
        transverse = np.maximum(0.0, 1.0 - self.rest / safe)
        # df/dx = -k [u u^T + t (I - u u^T)] = -k t I - k (1 - t) u u^T, df/dv = -kd u u^T
        return LinearizedPairs(self.pairs, u, -self.stiffness * transverse,
                               -self.stiffness * (1.0 - transverse), -self.damping, self._flat)

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
    """df/dx and df/dv of pair forces, blocks B acting on x_i - x_j (row i gets B (u_i - u_j),
    row j the opposite — [[B, -B], [-B, B]] on the pair), kept in the compact form of a spring:
    df/dx = x_iso I + x_axis u u^T, df/dv = v_axis u u^T per spring, u its unit direction.
    ``pairs`` (s, 2) is the spring set's fixed index array (the pattern cache keys on it)."""

    pairs: np.ndarray
    u: np.ndarray
    x_iso: np.ndarray
    x_axis: np.ndarray
    v_axis: np.ndarray
    flat: np.ndarray  # flat_index of [i, j]: the spring set's, computed once

    @property
    def clique(self) -> np.ndarray:
        return self.pairs

    def blocks(self, cx: float, cv: float) -> np.ndarray:
        """(s, 3, 3) blocks of cx df/dx + cv df/dv."""
        u = self.u
        out = (cx * self.x_axis + cv * self.v_axis)[:, None, None] * u[:, :, None] * u[:, None, :]
        out[:, [0, 1, 2], [0, 1, 2]] += (cx * self.x_iso)[:, None]
        return out

    @property
    def kx(self) -> np.ndarray:
        return self.blocks(1.0, 0.0)

    @property
    def kv(self) -> np.ndarray:
        return self.blocks(0.0, 1.0)

    def add_to(self, builder, cx: float, cv: float) -> None:
        """Blocks of cx df/dx + cv df/dv into a :class:`~.sparse.MatrixBuilder`."""
        builder.add_pairs(self.pairs, self.blocks(cx, cv))

    def product(self, cx: float, cv: float, w: np.ndarray, out: np.ndarray) -> None:
        """out += (cx df/dx + cv df/dv) w, matrix-free (for a one-off product)."""
        i, j = self.pairs[:, 0], self.pairs[:, 1]
        d = np.take(w, i, axis=0, mode="clip") - np.take(w, j, axis=0, mode="clip")
        along = (cx * self.x_axis + cv * self.v_axis) * _dot(self.u, d)
        df = (cx * self.x_iso)[:, None] * d + along[:, None] * self.u
        scatter_add(out, None, np.concatenate([df, -df]), self.flat)


@dataclass(frozen=True)
class LinearizedHinges:
    """Gauss-Newton bending Jacobian: df/dx = -k g g^T, df/dv = -kd g g^T over each hinge's four
    vertices, g the dihedral gradients (h, 4, 3) — symmetric negative semi-definite, as CG
    needs."""

    hinge: np.ndarray
    grad: np.ndarray
    stiffness: float
    damping: float

    @property
    def clique(self) -> np.ndarray:
        return self.hinge

    def add_to(self, builder, cx: float, cv: float) -> None:
        """cx df/dx + cv df/dv = -(cx k + cv kd) g g^T into a :class:`~.sparse.MatrixBuilder`."""
        builder.add_rank_one(self.hinge, self.grad, -(cx * self.stiffness + cv * self.damping))

    def product(self, cx: float, cv: float, u: np.ndarray, out: np.ndarray) -> None:
        """out += (cx df/dx + cv df/dv) u, matrix-free (for a one-off product)."""
        c = cx * self.stiffness + cv * self.damping
        w = c * np.einsum("hkc,hkc->h", self.grad, u[self.hinge])
        scatter_add(out, self.hinge.ravel(), (-w[:, None, None] * self.grad).reshape(-1, 3))


def dihedral_gradients(x: np.ndarray, hinge: np.ndarray) -> np.ndarray:
    """d(theta)/dx of every hinge's dihedral angle: (h, 4, 3) for (e0, e1, w0, w1)."""
    return dihedral_angles_and_gradients(x, hinge)[1]


def dihedral_angles_and_gradients(x: np.ndarray, hinge: np.ndarray):
    """Signed dihedral angles theta (h,) [rad] (as :func:`topology.dihedral_angles`) and their
    gradients d(theta)/dx (h, 4, 3) for (e0, e1, w0, w1), sharing the face normals."""
    (x0, x1, x2, x3), e, length, n1, n2, theta = topology.hinge_geometry(x, hinge)
    safe = np.where(length > 1e-12, length, 1.0)
    a1 = n1 / np.maximum(_dot(n1, n1), 1e-24)[:, None]
    a2 = n2 / np.maximum(_dot(n2, n2), 1e-24)[:, None]
    grad = np.empty((len(hinge), 4, 3))
    grad[:, 2] = -safe[:, None] * a1
    grad[:, 3] = -safe[:, None] * a2
    grad[:, 0] = -(_dot(x2 - x1, e) / safe)[:, None] * a1 - (_dot(x3 - x1, e) / safe)[:, None] * a2
    grad[:, 1] = (_dot(x2 - x0, e) / safe)[:, None] * a1 + (_dot(x3 - x0, e) / safe)[:, None] * a2
    return theta, grad


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles wrapped into [-pi, pi): a hinge folded past pi still turns back the short way."""
    return np.remainder(a + np.pi, 2.0 * np.pi) - np.pi


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

    def __post_init__(self):
        object.__setattr__(self, "_flat", flat_index(np.asarray(self.hinge).ravel()))
        object.__setattr__(self, "_last", [None, None, None])  # x copy, x, gradients

    def _gradients(self, x: np.ndarray):
        """(theta, grad) at x, remembered so that :meth:`linearize` at the same, unchanged
        positions reuses the gradients (forces, then the Jacobian, of one implicit step)."""
        theta, grad = dihedral_angles_and_gradients(x, self.hinge)
        self._last[:] = [x.copy(), x, grad]
        return theta, grad

    def _forces(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        theta, grad = self._gradients(x)
        delta = wrap_angle(theta - self.rest)
        rate = np.einsum("hkc,hkc->h", grad, v[self.hinge])
        torque = self.stiffness * delta + self.damping * rate
        return -torque[:, None, None] * grad

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        if len(self.hinge):
            scatter_add(f_out, None, self._forces(p.x, p.v).reshape(-1, 3), self._flat)

    def linearize(self, p: ParticleView) -> LinearizedHinges:
        copy, same, grad = self._last
        if not (same is p.x and np.array_equal(copy, p.x)):
            grad = self._gradients(p.x)[1]
        return LinearizedHinges(self.hinge, grad, self.stiffness, self.damping)

    def energy(self, x: np.ndarray) -> float:
        """0.5 k sum (theta - theta0)^2 [J]."""
        turn = wrap_angle(topology.dihedral_angles(x, self.hinge) - self.rest)
        return 0.5 * self.stiffness * float(np.vdot(turn, turn))


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

    def linearize(self, p: ParticleView) -> LinearizedVertices:
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
    """df/dx and df/dv as per-vertex (s, 3, 3) blocks on the diagonal."""

    index: np.ndarray
    kx: np.ndarray
    kv: np.ndarray

    clique = None  # couples no two vertices

    def add_to(self, builder, cx: float, cv: float) -> None:
        builder.add_diagonal(self.index, cx * self.kx + cv * self.kv)

    def product(self, cx: float, cv: float, u: np.ndarray, out: np.ndarray) -> None:
        """out += (cx df/dx + cv df/dv) u (for a one-off product)."""
        scatter_add(out, self.index, np.einsum("sab,sb->sa", cx * self.kx + cv * self.kv,
                                                u[self.index]))


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


@dataclass(frozen=True)
class MassShared:
    """A particle force object (drag, attractor, vortex, ...) acting on a whole spring mesh as
    on one particle: each vertex gets the force at its own position and velocity times its share
    of the mesh's mass, so the mesh as a whole feels what one particle there would, however
    finely it is subdivided.

    Args:
        force: anything with ``apply(p, f_out)``. share: (n,) vertex mass / total mass.
    """

    force: object
    share: np.ndarray

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        f = np.zeros_like(f_out)
        self.force.apply(p, f)
        f_out += self.share[:, None] * f
