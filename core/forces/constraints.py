"""Hard constraints on a point set: Witkin & Baraff's constraint forces from Lagrange multipliers,
then a projection back onto the constraints after each step.

Forces (inside every derivative evaluation, after all other forces Q have accumulated)::

    J W J^T lambda = -J' v - J W Q - ks C - kd C'      constraint force  Q^ = J^T lambda

W the inverse masses; ks, kd Witkin's drift feedback (:class:`Feedback`, off by default: the
projection below removes drift exactly). These forces do no work on the constrained motion, so
a higher-order integrator keeps its order on it. What discretisation leaves of C and C' is then
removed after the step (:meth:`HardConstraints.project`):

- after a higher-order step (midpoint, RK4, RK45), Cline & Pai's post-stabilisation: a few
  Newton steps move the positions back along W J^T, then the velocities lose their component
  along the constraint gradients;
- after a first-order step (symplectic Euler, implicit), the positions move along W J^T of the
  step's *start* and the velocities by the same displacement over h — Andersen's RATTLE, whose
  energy error stays bounded where the post-stabilised symplectic Euler gains energy without
  bound (a bead whirling round a wire: 1.2 m g R in 10 s at h = 1/240 s, RATTLE 0.013).

Both move the points only through the rows' own J, so rods between points conserve linear and
angular momentum.

The system matrix J W J^T couples two rows only where they share a point: it is built sparse
(coordinate form) from the rows' touching points, solved directly while small and by conjugate
gradients (Jacobi preconditioned) when large.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..integrators import bicgstab
from ..validate import non_negative
from .constraint_rows import NO_POINT, Rows, gather
from .springs import scatter_add

DENSE_ROWS = 600  # up to this many rows the system is solved directly
CG_ITERATIONS = 4000  # cap of the conjugate-gradient solve of larger systems
CG_TOLERANCE = 1e-12  # relative residual of the conjugate-gradient solve
PROJECTIONS = 8  # Newton steps of the position projection (at most; it stops at the tolerance)
FALLBACK_PROJECTIONS = 16  # more when RATTLE's falls back to the current gradients
RATTLE_CONTRACTION = 0.5  # RATTLE's Newton step must halve |C|, or it falls back
REGULARISE = 1e-12  # relative diagonal shift: redundant rows (a rod between two pins) stay solvable


@dataclass(frozen=True)
class Feedback:
    """Witkin's drift feedback of the constraint forces: ks [1/s^2] on C and kd [1/s] on C'.
    Off by default. Gains tied to the step (ks ~ 1/h^2) would cost the integrator its order:
    they turn the O(h^5) stage errors of RK4 into O(1) forces (measured: RK4's energy error then
    halves with h instead of falling 32-fold)."""

    stiffness: float = 0.0
    damping: float = 0.0

    def __post_init__(self):
        non_negative("constraint feedback", stiffness=self.stiffness, damping=self.damping)


@dataclass
class Projection:
    """What one projection did: the largest |C| left [m] and rows solved."""

    residual: float
    rows: int


class _System:
    """J_left W J_right^T of one set of rows, sparse, with the products the solves need (J_right
    defaults to J_left: the symmetric J W J^T; RATTLE's Newton step pairs the rows at the new
    positions with those at the step's start)."""

    def __init__(self, rows: Rows, w: np.ndarray, right: Rows | None = None):
        self.rows = rows
        self.symmetric = right is None
        m = rows.count
        point, left = rows.point, rows.jac
        right_jac = left if right is None else right.jac
        # every (row, slot) touching a point, grouped by point: rows sharing a point couple
        entry_row, entry_slot = np.nonzero(point != NO_POINT)
        entry_point = point[entry_row, entry_slot]
        order = np.argsort(entry_point, kind="stable")
        er, es, ep = entry_row[order], entry_slot[order], entry_point[order]
        wl = left[er, es] * w[ep][:, None]  # W J_left^T, per entry
        jr = right_jac[er, es]
        ij, jj, vals = [], [], []
        for d in range(len(ep)):  # pairs of entries of the same point, d apart in the order
            same = np.nonzero(ep[d:] == ep[:len(ep) - d])[0] if d else np.arange(len(ep))
            if len(same) == 0:
                break
            ij.append(er[same])
            jj.append(er[same + d])
            vals.append(np.einsum("ij,ij->i", wl[same], jr[same + d]))
            if d:  # the other half
                ij.append(er[same + d])
                jj.append(er[same])
                vals.append(np.einsum("ij,ij->i", wl[same + d], jr[same]))
        self.i = np.concatenate(ij) if ij else np.zeros(0, np.int64)
        self.j = np.concatenate(jj) if jj else np.zeros(0, np.int64)
        self.v = np.concatenate(vals) if vals else np.zeros(0)
        on_diagonal = self.i == self.j
        self.diag = np.bincount(self.i[on_diagonal], weights=self.v[on_diagonal], minlength=m)
        self.shift = REGULARISE * (float(np.abs(self.diag).max()) if m else 0.0)
        self.m = m
        self._inverse = None
        # rows coupled only to their neighbours in order (a chain's rods in order along it)
        self.tridiagonal = bool(np.all(np.abs(self.i - self.j) <= 1))

    def _cyclic_reduction(self, d: np.ndarray) -> np.ndarray:
        """Parallel cyclic reduction of a tridiagonal system: each pass folds every row's
        neighbours at distance s into it (s doubling), log2(m) vectorised passes. Stable for a
        symmetric positive definite matrix, which J W J^T is."""
        m = self.m
        lower, upper = self.j == self.i - 1, self.j == self.i + 1
        a, c = np.zeros(m), np.zeros(m)
        np.add.at(a, self.i[lower], self.v[lower])
        np.add.at(c, self.i[upper], self.v[upper])
        b = self.diag + self.shift
        d = d.astype(np.float64).copy()
        s = 1
        while s < m:
            # rows i - s and i + s (zero rows past the ends)
            up = np.arange(m) - s
            dn = np.arange(m) + s
            has_up, has_dn = up >= 0, dn < m
            up, dn = np.where(has_up, up, 0), np.where(has_dn, dn, 0)
            k1 = np.where(has_up, a / b[up], 0.0)
            k2 = np.where(has_dn, c / b[dn], 0.0)
            b, d, a, c = (b - k1 * c[up] * has_up - k2 * a[dn] * has_dn,
                          d - k1 * d[up] * has_up - k2 * d[dn] * has_dn,
                          -k1 * a[up] * has_up, -k2 * c[dn] * has_dn)
            s *= 2
        return d / b

    def dense(self) -> np.ndarray:
        """The (m, m) matrix (regularised)."""
        a = np.zeros((self.m, self.m))
        np.add.at(a, (self.i, self.j), self.v)
        a[np.diag_indices(self.m)] += self.shift
        return a

    def matvec(self, y: np.ndarray) -> np.ndarray:
        return np.bincount(self.i, weights=self.v * y[self.j], minlength=self.m) + self.shift * y

    def solve(self, b: np.ndarray) -> np.ndarray:
        if self.m == 0:
            return b
        if self.tridiagonal:
            return self._cyclic_reduction(b)
        if self.m <= DENSE_ROWS:
            if self._inverse is None:
                self._inverse = np.linalg.inv(self.dense())
            return self._inverse @ b
        if not self.symmetric:
            return bicgstab(self.matvec, b, CG_TOLERANCE, CG_ITERATIONS)[0]
        return self._cg(b)

    def _cg(self, b: np.ndarray) -> np.ndarray:
        """Jacobi-preconditioned conjugate gradients."""
        precond = 1.0 / np.where(self.diag > 0.0, self.diag + self.shift, 1.0)
        y = np.zeros_like(b)
        r = b.copy()
        z = precond * r
        p = z.copy()
        rz = float(r @ z)
        limit = (CG_TOLERANCE * float(np.linalg.norm(b))) ** 2
        for _ in range(CG_ITERATIONS):
            if float(r @ r) <= limit:
                break
            ap = self.matvec(p)
            alpha = rz / float(p @ ap)
            y += alpha * p
            r -= alpha * ap
            z = precond * r
            rz, rz_old = float(r @ z), rz
            p = z + (rz / rz_old) * p
        return y

    def apply_j(self, u: np.ndarray) -> np.ndarray:
        """J u for per-point vectors u (n, 3): (m,)."""
        return _row_dot(self.rows, u)

    def apply_jt(self, y: np.ndarray, n: int) -> np.ndarray:
        """J^T y as per-point vectors (n, 3)."""
        return _scatter(self.rows, y, n)


def _row_dot(rows: Rows, u: np.ndarray) -> np.ndarray:
    out = np.zeros(rows.count)
    for slot in (0, 1):
        p = rows.point[:, slot]
        used = p != NO_POINT
        out[used] += np.einsum("ij,ij->i", rows.jac[used, slot], u[p[used]])
    return out


def _scatter(rows: Rows, y: np.ndarray, n: int) -> np.ndarray:
    """J^T y: each row's impulse y along its gradient, summed per point (n, 3)."""
    out = np.zeros((n, 3))
    for slot in (0, 1):
        p = rows.point[:, slot]
        used = p != NO_POINT
        scatter_add(out, p[used], rows.jac[used, slot] * y[used, None])
    return out


class HardConstraints:
    """Hard constraints of one point set.

    Args:
        kinds: constraint kinds (:mod:`.constraint_rows`: rods, tethers, planes, pins, ...),
            each with ``rows(x, v, t)``.
        feedback: :class:`Feedback`. tolerance: |C| [m] the projection stops at.
    """

    def __init__(self, kinds: list, feedback: Feedback = Feedback(), tolerance: float = 1e-10,
                 bodies=None):
        self.kinds = list(kinds)
        self.ks, self.kd = feedback.stiffness, feedback.damping
        self.tolerance = tolerance
        self.bodies = bodies

    def rows(self, x: np.ndarray, v: np.ndarray, t: float, bodies: bool = False) -> Rows:
        """The kinds' rows (and, with ``bodies``, the rows to the bodies after them)."""
        extra = [self.bodies] if bodies and self.bodies is not None else []
        return gather([k.rows(x, v, t) for k in self.kinds + extra])

    # -- constraint forces ----------------------------------------------------------------------
    def force(self, x: np.ndarray, v: np.ndarray, t: float, inverse_mass: np.ndarray,
              f: np.ndarray) -> np.ndarray:
        """Add the constraint force J^T lambda to the accumulated forces ``f`` (n, 3) [N];
        returns lambda (m,). The bodies' rows join (their bodies accelerate with their own
        forces and the rows', :meth:`_solve`), and the bodies are told their part."""
        rows = self.rows(x, v, t, bodies=True)
        if rows.count == 0:
            return np.zeros(0)
        system = _System(rows, inverse_mass)
        b = (-rows.jdot_v - system.apply_j(inverse_mass[:, None] * f)
             - self.ks * rows.c - self.kd * rows.cdot)
        if self.bodies is not None:  # C'' = J a + U (bodies' accelerations) + J' v
            b[rows.count - self.bodies.count:] -= \
                self.bodies.columns() @ self.bodies.free_acceleration()
        lam, accel = self._solve(system, b)
        f += system.apply_jt(lam, len(x))
        if accel is not None:
            self.bodies.forces(lam[rows.count - self.bodies.count:], accel)
        return lam

    def constrain(self, view, f: np.ndarray) -> None:
        """The force pass of a derivative (``view``: a ParticleView); points of infinite mass
        (pinned) are not moved by it."""
        self.force(view.x, view.v, view.t, _inverse(view.mass), f)

    # -- projection -----------------------------------------------------------------------------
    def project(self, x: np.ndarray, v: np.ndarray, t: float, inverse_mass: np.ndarray,
                start: np.ndarray | None = None, h: float = 0.0) -> Projection:
        """Move ``x`` and ``v`` (n, 3) in place onto the constraints at time ``t`` (mass-weighted
        least change: impulses along J^T). With ``start`` (the positions at the step's start, a
        first-order step of length ``h``) the positions move along its J and the velocities
        with them (RATTLE); without, along their own J (post-stabilisation). The ``bodies``
        move with the points (:meth:`_solve`)."""
        n = len(x)
        rows = self.rows(x, v, t, bodies=True)
        if rows.count == 0:
            return Projection(0.0, 0)
        first = None if start is None else self.rows(start, v, t, bodies=True)
        residual = float(np.max(np.abs(rows.c)))
        for _ in range(PROJECTIONS + (0 if first is None else FALLBACK_PROJECTIONS)):
            if residual <= self.tolerance:
                break
            if first is None:  # Newton along the current gradients
                system = _System(rows, inverse_mass)
                delta, dq = self._solve(system, -rows.c)
                dx = inverse_mass[:, None] * system.apply_jt(delta, n)
            else:  # Newton for the multipliers along the start's gradients: J W J0^T
                delta, dq = self._solve(_System(rows, inverse_mass, first), -rows.c)
                dx = inverse_mass[:, None] * _scatter(first, delta, n)
            x += dx
            if dq is not None:
                self.bodies.move(dq)
            moved = self.rows(x, v, t, bodies=True)
            worse = float(np.max(np.abs(moved.c)))
            if first is not None and not worse < RATTLE_CONTRACTION * residual:
                # the start's gradients cannot reach the constraints (points turned far in one
                # step): undo, and go on along the current ones (dissipative, but converges)
                x -= dx
                if dq is not None:
                    self.bodies.move(-dq)
                first = None
                continue
            if start is not None:
                v += dx / h
                if dq is not None:
                    self.bodies.push(dq / h, delta[rows.count - self.bodies.count:] / h)
            rows, residual = moved, worse
        if self.bodies is not None:  # the velocities (points' and bodies') as they are now
            rows = self.rows(x, v, t, bodies=True)
        system = _System(rows, inverse_mass)
        lam, du = self._solve(system, -rows.cdot)
        v += inverse_mass[:, None] * system.apply_jt(lam, n)
        if du is not None:
            self.bodies.push(du, lam[rows.count - self.bodies.count:])
        return Projection(float(np.max(np.abs(rows.c))), rows.count)

    def _solve(self, system: _System, b: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """The multipliers of ``system`` with right-hand side b, and the bodies' motion
        M^-1 U^T lambda (None without bodies). The bodies' rows come last; U, their gradient
        in the bodies' motions, adds U M^-1 U^T to J W J^T (the bodies' give: a point tied
        to a body has more rows than it has freedoms, so the points' part alone is singular
        and the sum is solved whole)."""
        if self.bodies is None:
            return system.solve(b), None
        u = np.zeros((system.m, len(self.bodies.mass)))
        u[system.m - self.bodies.count:] = self.bodies.columns()
        give = np.linalg.solve(self.bodies.mass, u.T)  # M^-1 U^T
        if system.m <= DENSE_ROWS:
            lam = np.linalg.solve(system.dense() + u @ give, b)
        else:
            lam = bicgstab(lambda y: system.matvec(y) + u @ (give @ y), b, CG_TOLERANCE,
                           CG_ITERATIONS)[0]
        return lam, give @ lam


def _inverse(mass: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return np.where(np.isfinite(mass) & (mass > 0.0), 1.0 / mass, 0.0)
