"""Forces of spring meshes beyond the shared damped springs (:mod:`physanim.core.forces.springs`,
whose Jacobian interface these follow): angular springs on hinges (bending), viscous air drag,
and any point force shared over the mesh by vertex mass.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..forces import ParticleView
from ..forces.springs import LastGeometry, LinearizedVertices, flat_index, scatter_add
from ..transforms import divide_rows, dot_rows, scale_rows
from . import topology

FADE_AREA = 0.1  # of its rest area: a hinge's triangle squashed smaller fades its bending out


@dataclass(frozen=True)
class LinearizedHinges:
    """Gauss-Newton bending Jacobian: df/dx = -k g g^T, df/dv = -kd g g^T over each hinge's four
    vertices, g the dihedral gradients (h, 4, 3) — symmetric negative semi-definite, as CG
    needs."""

    hinge: np.ndarray
    grad: np.ndarray
    stiffness: float
    damping: float
    flat: np.ndarray | None = None  # flat_index of the hinge's vertices, when known

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
        scatter_add(out, self.hinge.ravel(), (-w[:, None, None] * self.grad).reshape(-1, 3),
                    self.flat)


def dihedral_gradients(geometry: tuple) -> np.ndarray:
    """The gradients d(theta)/dx (h, 4, 3) of the signed dihedral angles (as
    :func:`topology.dihedral_angles`) for (e0, e1, w0, w1), from
    :func:`topology.hinge_geometry`'s results (sharing its face normals)."""
    (x0, x1, x2, x3), e, length, n1, n2, _ = geometry
    safe = np.where(length > 1e-12, length, 1.0)
    a1 = divide_rows(n1, np.maximum(dot_rows(n1, n1), 1e-24))
    a2 = divide_rows(n2, np.maximum(dot_rows(n2, n2), 1e-24))
    grad = np.empty((len(length), 4, 3))
    scale_rows(a1, -safe, out=grad[:, 2])
    scale_rows(a2, -safe, out=grad[:, 3])
    # (by columns: numpy runs (h, 1) x (h, 3) broadcasts row by row; the same values)
    w20, w30 = dot_rows(x2 - x1, e) / safe, dot_rows(x3 - x1, e) / safe
    w21, w31 = dot_rows(x2 - x0, e) / safe, dot_rows(x3 - x0, e) / safe
    for k in range(3):
        column = grad[:, 0, k]
        np.multiply(a1[:, k], -w20, out=column)
        column -= w30 * a2[:, k]
        column = grad[:, 1, k]
        np.multiply(a1[:, k], w21, out=column)
        column += w31 * a2[:, k]
    return grad


def hinge_normals(x: np.ndarray, hinge: np.ndarray) -> np.ndarray:
    """(h, 2) the lengths of each hinge's two unnormalised face normals at ``x`` (twice the
    triangles' areas) [m^2]: at rest, what :class:`AngularSprings` fades squashed ones by."""
    return _normal_lengths(topology.hinge_geometry(np.asarray(x, np.float64),
                                                   np.asarray(hinge)))


def _normal_lengths(geometry) -> np.ndarray:
    """(h, 2) |n1|, |n2| of :func:`topology.hinge_geometry`'s results."""
    return np.sqrt(np.stack([dot_rows(geometry[3], geometry[3]),
                             dot_rows(geometry[4], geometry[4])], axis=1))


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles wrapped into [-pi, pi): a hinge folded past pi still turns back the short way."""
    return np.remainder(a + np.pi, 2.0 * np.pi) - np.pi


@dataclass(frozen=True)
class AngularSprings:
    """Angular spring-dampers on hinges: the torque -[k (theta - theta0) + kd theta_dot] about
    the shared edge, applied as forces along d(theta)/dx (they sum to zero force and zero torque).

    A hinge whose triangle is squashed flat (its corners in a line: a cloth standing on its
    edge crumples along the ground) has no dihedral angle: the gradient grows as one over the
    triangle's area and the angle jumps by pi as the triangle turns over. Below FADE_AREA of its
    rest area a triangle fades its hinge out by s = area / (FADE_AREA rest area): the torque by
    s^2 and the gradient it acts along by s, so the force and the Jacobian stay bounded (a
    cloth landing corner-down pushed its solve to forces of 1e14 N and gained energy; with BDF2
    it blew up).

    Args: hinge: (h, 4) vertex indices (e0, e1, w0, w1). rest: (h,) theta0 [rad].
    stiffness: k [N m/rad]. damping: kd [N m s/rad]. rest_normals: (h, 2) the lengths of the
    two triangles' unnormalised normals (twice their areas) at rest [m^2]; None: no fading.
    """

    hinge: np.ndarray
    rest: np.ndarray
    stiffness: float
    damping: float
    rest_normals: np.ndarray | None = None

    def __post_init__(self):
        # derived once from the frozen fields (scatter order of the (h, 4) hinge vertices)
        object.__setattr__(self, "_flat", flat_index(np.asarray(self.hinge).ravel()))
        object.__setattr__(self, "_last", _LastGeometry())

    def _geometry(self, x: np.ndarray, gradients: bool = True):
        """(theta, grad, fade) at x — grad None unless ``gradients``, fade None when no hinge
        fades — from the last hinge geometry while x is the same: an implicit step asks at its
        start for the forces, the energy and the Jacobian, and the energy at its end (angles
        only: the gradients follow from the same geometry if the next step starts there) is the
        next step's start. grad is the angle's gradient times the fade s (class docstring)."""
        last = self._last
        if last.x is None or not np.array_equal(last.x, x):
            last.x, last.geometry, last.grad = x.copy(), topology.hinge_geometry(x, self.hinge), None
            last.fade = self._fade(last.geometry)
        if gradients and last.grad is None:
            last.grad = dihedral_gradients(last.geometry)
            if last.fade is not None:
                last.grad *= last.fade[:, None, None]
        return last.geometry[5], last.grad, last.fade

    def _fade(self, geometry) -> np.ndarray | None:
        """s (h,) of each hinge (class docstring), or None when every hinge keeps its whole
        stiffness."""
        rest = getattr(self, "rest_normals", None)  # (a solver saved before hinges faded)
        if rest is None:
            return None
        size = _normal_lengths(geometry)
        least = FADE_AREA * rest
        if not (size < least).any():
            return None
        share = np.divide(size, least, out=np.ones_like(size), where=size < least)
        return share.min(axis=1)

    def _forces(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        theta, grad, fade = self._geometry(x)
        delta = wrap_angle(theta - self.rest)
        if fade is not None:
            delta = delta * fade
        rate = np.einsum("hkc,hkc->h", grad, v[self.hinge])
        torque = self.stiffness * delta + self.damping * rate
        return -torque[:, None, None] * grad

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        if len(self.hinge):
            scatter_add(f_out, None, self._forces(p.x, p.v).reshape(-1, 3), self._flat)

    def linearize(self, p: ParticleView) -> LinearizedHinges:
        """Jacobian blocks at ``p.x``; the gradients are those :meth:`apply` computed when it
        was asked at the same positions (compared by value), else computed here."""
        return LinearizedHinges(self.hinge, self._geometry(p.x)[1], self.stiffness, self.damping,
                                self._flat)

    def energy(self, x: np.ndarray) -> float:
        """0.5 k sum (s (theta - theta0))^2 [J] (s: the fade, class docstring)."""
        theta, _, fade = self._geometry(x, gradients=False)
        turn = wrap_angle(theta - self.rest)
        if fade is not None:
            turn *= fade
        return 0.5 * self.stiffness * float(np.vdot(turn, turn))


class _LastGeometry(LastGeometry):
    """The hinge geometry :meth:`AngularSprings._geometry` computed last, with its gradients
    and fade (a cache: copies and pickles empty)."""

    def __init__(self):
        super().__init__()
        self.grad = self.fade = None


@dataclass(frozen=True)
class LinearDrag:
    """Viscous air drag f = -k m v (k [1/s] per unit mass, so heavy and light cloth slow alike)."""

    k: float

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        if self.k:
            f_out -= scale_rows(p.v, self.k * p.mass)

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


@dataclass(frozen=True)
class ConstantForces:
    """Forces (n, 3) [N] on the vertices, constant over a sub-step (self-collision's carried
    contact forces): the potential -sum f . x, so the implicit step's energy check counts
    their work as it counts gravity's."""

    f: np.ndarray

    def apply(self, p: ParticleView, f_out: np.ndarray) -> None:
        f_out += self.f

    def energy(self, x: np.ndarray) -> float:
        return -float(np.vdot(self.f, x))
