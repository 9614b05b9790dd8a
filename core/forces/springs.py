"""Damped springs for any point set: between pairs of its points (:class:`DampedSprings`) or
from its points to moving anchors (:class:`AnchorSprings`), one formula for both
(:func:`spring_forces`), with the Jacobians an implicit integrator needs.

Each force object has ``apply(p, f_out)`` (see :mod:`.fields`) and ``linearize(p)``, which
returns its Jacobian at that state as 3 x 3 blocks: ``clique`` names the points it couples
(None: per-point blocks only), ``add_to(builder, cx, cv)`` puts cx df/dx + cv df/dv into an
assembled block-sparse matrix (``MatrixBuilder`` of :mod:`physanim.core.springs.sparse`) and
``product(cx, cv, u, out)`` applies it once matrix-free — vectorised, no per-spring Python loop.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import divide_rows, dot_rows, scale_rows
from .fields import ParticleView


def flat_index(index: np.ndarray) -> np.ndarray:
    """Indices of the x, y, z components of rows ``index`` in a flattened (n, 3) array."""
    return (np.asarray(index)[:, None] * 3 + np.arange(3)).ravel()


def scatter_add(out: np.ndarray, index: np.ndarray, values: np.ndarray,
                flat: np.ndarray | None = None) -> None:
    """out[index] += values, repeated indices summed, for out (n, k) and values (m, k) (or
    shaped as index, then k): one flat bincount when ``flat`` = flat_index(index) is given
    (k = 3, precomputed by callers that scatter often), else one per column (twice as fast as
    building it, eight times np.add.at). Shared by forces, contact pairs and the rigid
    solvers' warm starts."""
    if flat is None:
        index = np.asarray(index).ravel()
        values = values.reshape(len(index), out.shape[1])
        for c in range(values.shape[1]):
            out[:, c] += np.bincount(index, weights=values[:, c], minlength=len(out))
        return
    out += np.bincount(flat, weights=values.ravel(), minlength=out.size).reshape(out.shape)


def spring_geometry(l: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit directions u (s, 3), lengths |l| (s,) and lengths safe to divide by (1 where |l| is
    0: a spring of zero length pushes nowhere) of spring vectors l (s, 3)."""
    length = np.sqrt(dot_rows(l, l))
    safe = np.where(length > 1e-12, length, 1.0)
    return divide_rows(l, safe), length, safe


def spring_forces(l: np.ndarray | None, ldot: np.ndarray, rest, stiffness, damping,
                  geometry: tuple | None = None):
    """Witkin & Baraff's damped spring, the one formula every spring here uses: the force on
    the first end, f = -[ks (|l| - r) + kd (l_dot . l)/|l|] l/|l| (the second end gets -f).

    Args: l, ldot: (s, 3) x_a - x_b and v_a - v_b. rest, stiffness, damping: (s,) or scalars.
    geometry: :func:`spring_geometry` of l when known (then l is not read).
    Returns: (f (s, 3), u, |l|, safe |l|) as :func:`spring_geometry`.
    """
    u, length, safe = spring_geometry(l) if geometry is None else geometry
    f = scale_rows(u, -(stiffness * (length - rest) + damping * dot_rows(ldot, u)))
    return f, u, length, safe


class LastGeometry:
    """The geometry a force computed last and the positions ``x`` it was computed at: a cache
    of a pure function, which copies and pickles empty (a saved bake state holds none of it)."""

    def __init__(self):
        self.x = self.geometry = None

    def __reduce__(self):
        return type(self), ()

    def __deepcopy__(self, memo):
        return type(self)()


@dataclass(frozen=True)
class DampedSprings:
    """Damped springs between point pairs of one set (a spring mesh's edges, linked particles):

    f_i = -[ks (|l| - r) + kd (l_dot . l)/|l|] l/|l|,  l = x_i - x_j,  f_j = -f_i.

    Args: i, j: (s,) point indices. rest: (s,) r [m]. stiffness, damping: ks [N/m] and kd
    [N s/m], per spring (s,) or one value for all (one set holds every family of a mesh with
    its own constants). keep: keep the last positions' geometry (:meth:`geometry`; a set
    asked several times at the same positions: a spring mesh's).
    """

    i: np.ndarray
    j: np.ndarray
    rest: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    keep: bool = False

    def __post_init__(self):
        count = len(self.i)
        for key in ("rest", "stiffness", "damping"):
            value = np.asarray(getattr(self, key), dtype=np.float64)
            object.__setattr__(self, key, np.broadcast_to(value, (count,)) if value.ndim == 0
                               else value)
        # (s, 2): one fixed array naming the pairs, so a solver's block pattern is built once
        object.__setattr__(self, "pairs", np.stack([np.asarray(self.i, np.int64),
                                                    np.asarray(self.j, np.int64)], axis=1))
        object.__setattr__(self, "_flat", flat_index(np.concatenate([self.i, self.j])))
        object.__setattr__(self, "_last", LastGeometry())

    def _l(self, a: np.ndarray) -> np.ndarray:
        return np.take(a, self.i, axis=0, mode="clip") - np.take(a, self.j, axis=0, mode="clip")

    def geometry(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:func:`spring_geometry` of the springs at ``x``, from the last one while x is the
        same: an implicit step asks at its start for the forces and the Jacobian, and the
        energy at its end is the next step's start."""
        if not self.__dict__.get("keep"):  # (a set saved before it could keep one: not)
            return spring_geometry(self._l(x))
        last = self._last
        if last.x is None or not np.array_equal(last.x, x):
            last.x, last.geometry = x.copy(), spring_geometry(self._l(x))
        return last.geometry

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        if len(self.i) == 0:
            return
        f, *_ = spring_forces(None, self._l(p.v), self.rest, self.stiffness, self.damping,
                              self.geometry(p.x))
        scatter_add(f_out, None, np.concatenate([f, -f]), self._flat)

    def linearize(self, p: ParticleView) -> LinearizedPairs:
        """Jacobian blocks at this state. The transverse stiffness (1 - r/|l|) is clamped at 0
        so a compressed spring never makes the implicit system indefinite (Choi & Ko)."""
        u, _, safe = self.geometry(p.x)
        transverse = np.maximum(0.0, 1.0 - self.rest / safe)
        # df/dx = -k [u u^T + t (I - u u^T)] = -k t I - k (1 - t) u u^T, df/dv = -kd u u^T
        return LinearizedPairs(self.pairs, u, -self.stiffness * transverse,
                               -self.stiffness * (1.0 - transverse), -self.damping, self._flat)

    def energy(self, x: np.ndarray) -> float:
        """0.5 sum ks (|l| - r)^2 [J]."""
        if len(self.i) == 0:
            return 0.0
        _, length, _ = self.geometry(x)
        stretch = length - self.rest
        return 0.5 * float(np.dot(self.stiffness, stretch * stretch))

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
        along = cx * self.x_axis + cv * self.v_axis
        iso = cx * self.x_iso
        out = np.empty((len(u), 3, 3))
        for a in range(3):  # column by column: numpy runs broadcasts over 3 slowly
            scaled = along * u[:, a]
            for b in range(3):
                np.multiply(scaled, u[:, b], out=out[:, a, b])
            out[:, a, a] += iso
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
        along = (cx * self.x_axis + cv * self.v_axis) * dot_rows(self.u, d)
        df = (cx * self.x_iso)[:, None] * d + along[:, None] * self.u
        scatter_add(out, None, np.concatenate([df, -df]), self.flat)


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
        radial, *_ = spring_forces(l, ldot, self.rest, self.stiffness, self.damping)
        linear = -self.stiffness[:, None] * l - self.damping[:, None] * ldot
        scatter_add(f_out, self.index, np.where(zero[:, None], linear, radial))

    def linearize(self, p: ParticleView) -> LinearizedVertices:
        a, _ = self.anchor(p.t)
        u, _, safe = spring_geometry(p.x[self.index] - a)
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
