"""Implicit (backward) Euler for spring meshes, Baraff & Witkin's "Large steps in cloth
simulation" (1998): one linearised step solved by preconditioned conjugate gradients on the
spring Jacobians, with pinned vertices handled by filtering (their velocity change is given).

    (M - h df/dv - h^2 df/dx) dv = h (f0 + h df/dx v0),   v1 = v0 + dv,   x1 = x0 + h v1

The matrix is symmetric (spring Jacobians with the compressed-spring term clamped are
symmetric negative semi-definite), so CG applies. It is assembled once per linearisation into
a block-sparse pattern built from the topology on the first step (:mod:`.sparse`), so each CG
product is one gather and one batched matrix product; the preconditioner is aggregation
multigrid (:mod:`.multigrid`: iterations barely grow with stiffness) or block Jacobi, and the
first guess extrapolates the previous steps' dv. As in Baraff & Witkin, the solve is inexact:
CG stops at the tolerance or the iteration cap; when the step gained energy, further Newton
iterations re-linearise at its end.
Every CG iterate lowers the A-norm of the error, so a capped solve is still a damped, stable
step; only a loss of positive definiteness or a non-finite value is an error.
"""
from __future__ import annotations

import numpy as np

from ..errors import SimulationError
from ..integrators import StepReport
from ..transforms import inverse3
from .multigrid import AggregationHierarchy
from .sparse import BlockMatrix, BlockPattern, MatrixBuilder


class BaraffWitkin:
    """Implicit Euler stepper with the entry point of every integrator: ``step(system, t, h)``.

    The system must offer ``mass`` (n,), ``free`` (n,) bool, ``pinned_velocity(t)`` (n, 3),
    ``weight_norm()`` (|M g| [N], the force scale residuals are judged against),
    ``forces_at(t, x, v) -> (n, 3)``, ``linearize(t, x, v)`` -> Jacobian blocks with
    ``clique`` (the fixed (m, k) index array of vertices they couple, or None for per-vertex
    blocks), ``add_to(builder, cx, cv)`` (puts cx df/dx + cv df/dv into a
    :class:`~.sparse.MatrixBuilder`) and ``product(cx, cv, u, out)`` (out += that matrix times
    u, matrix-free), ``contact`` (:class:`~physanim.core.contact.Contacts`: the vertices
    constrained to move with a surface along its normal) and ``x``/``v`` attributes it updates;
    optionally ``energy(x, v)``.

    Args:
        tolerance: relative residual at which CG stops. max_iterations: CG cap.
    """

    name = "IMPLICIT"
    stable_h_omega = None  # unconditionally stable

    TOLERANCE = 1e-3  # relative residual: Baraff & Witkin's inexact solve, visually converged

    PRECONDITIONERS = ("MULTIGRID", "JACOBI")

    def __init__(self, tolerance: float = TOLERANCE, max_iterations: int = 200,
                 newton_iterations: int = 4, preconditioner: str = "MULTIGRID"):
        if preconditioner not in self.PRECONDITIONERS:
            raise ValueError(f"preconditioner must be one of {self.PRECONDITIONERS} "
                             f"(got {preconditioner!r})")
        self.preconditioner = preconditioner
        self.tolerance = float(tolerance)
        self.max_iterations = int(max_iterations)
        # A second Newton iteration re-linearises at the end of the step when Baraff & Witkin's
        # single linearisation gained energy (stiff springs rotating within one large step);
        # systems that offer ``energy(x, v)`` are checked, others always iterate.
        self.newton_iterations = int(newton_iterations)
        # the last two steps' solutions: the next step's first guess extrapolates them linearly
        self._warm: list = []
        self._warm_t: float | None = None  # the step time of _warm[0]
        self._energy: tuple | None = None  # (x, v, energy) at the end of the last step
        # (cliques it was built from, BlockPattern, AggregationHierarchy or None)
        self._pattern: tuple | None = None
        self.last_residual = 0.0
        self.last_iterations = 0

    def step(self, system, t: float, h: float) -> StepReport:
        x0, v0 = system.x, system.v
        mass = system.mass[:, None]
        free = system.free[:, None]
        f0 = system.forces_at(t, x0, v0)

        # Constraints (Baraff & Witkin's filter): pinned vertices have a prescribed velocity
        # change; vertices pressed onto a collider have a prescribed normal velocity (the
        # surface's) and move freely along it.
        given = np.where(free, 0.0, system.pinned_velocity(t + h) - v0)
        contact = system.contact
        pressed, normal = np.zeros(0, np.int64), np.zeros((0, 3))
        if len(contact):
            push = np.einsum("ij,ij->i", f0[contact.index], contact.normal)
            # only where forces press inwards, or where the vertex is held (landing: the
            # solver's re-solve of a step in which it hit the surface, SpringMeshSolver.advance)
            keep = ((push < 0.0) | contact.held) & system.free[contact.index]
            pressed, normal = contact.index[keep], contact.normal[keep]
            vn = np.einsum("ij,ij->i", v0[pressed], normal)
            given[pressed] = (contact.normal_speed[keep] - vn)[:, None] * normal

        free_scale = free.astype(np.float64)

        def project(u: np.ndarray) -> np.ndarray:
            """Remove the constrained directions, in place (callers pass fresh arrays)."""
            u *= free_scale
            if len(pressed):
                un = np.einsum("ij,ij->i", u[pressed], normal)
                u[pressed] -= un[:, None] * normal
            return u

        # residuals are judged against the impulse gravity gives in one step (at least): near
        # equilibrium the right-hand side -> 0 and a purely relative test never stops
        floor = h * float(system.weight_norm())
        dv = given.copy()
        iterations_total, reaction = 0, None
        energy = getattr(system, "energy", None)
        e0 = None
        if energy is not None:
            e0 = self._known_energy(x0, v0)
            if e0 is None:
                e0 = energy(x0, v0)
        e_end = None
        for newton in range(self.newton_iterations):
            if newton > 0 and e0 is not None:
                e_end = energy(x0 + h * (v0 + dv), v0 + dv)
                if e_end <= e0:
                    break  # the linearised step already lost energy: no need to re-linearise
                e_end = None
            if newton == 0:  # Baraff & Witkin: linearise at (x0, v0), rhs h (f0 + h df/dx v0)
                blocks = system.linearize(t, x0, v0)
                rhs = f0.copy()
                for blk in blocks:
                    blk.product(h, 0.0, v0, rhs)
                rhs *= h
            else:  # Newton on g(dv) = M dv - h f(x0 + h (v0 + dv), v0 + dv)
                v1 = v0 + dv
                x1 = x0 + h * v1
                blocks = system.linearize(t + h, x1, v1)
                rhs = h * system.forces_at(t + h, x1, v1) - mass * dv
            matrix = self._assemble(blocks, system.mass, h)
            apply_a = matrix.__matmul__
            # rebuilt for every linearisation: a stiff mesh turning within the step changes its
            # matrix enough that the first one's preconditioner would cost hundreds of
            # iterations in the later Newton iterations
            precondition = self._preconditioner(
                self._filtered(matrix, system.free, pressed, normal), system.free)
            known = dv if newton == 0 else np.zeros_like(dv)
            b = project(rhs - (apply_a(known) if np.any(known) else 0.0))
            start = self._first_guess(b.shape, t) if newton == 0 else None
            scale = max(float(np.sqrt(np.sum(b * b))), floor)
            delta, iterations, residual = self._pcg(apply_a, b, precondition, project, start, scale)
            iterations_total += iterations
            if newton == 0:
                # a step solved again (landing constraints) replaces its own entry
                keep = self._warm[1:2] if t == self._warm_t else self._warm[:1]
                self._warm, self._warm_t = [delta.copy()] + keep, t
                reaction = apply_a(delta + known) - rhs  # the constraints' impulses
            dv = dv + delta
            self.last_residual = residual
        v1 = v0 + dv
        if len(pressed):
            # Coulomb friction is an impulse on the pressed vertices; the mesh takes it as a
            # whole (one more filtered solve), so a vertex that friction slows drags its
            # neighbours along instead of stretching the springs to them
            stop = self._friction(v1, pressed, normal, contact, reaction, mass)
            if np.any(stop):
                b = project(mass * stop)
                scale = max(float(np.sqrt(np.vdot(b, b))), floor)
                delta, iterations, _ = self._pcg(apply_a, b, precondition, project, None, scale)
                iterations_total += iterations
                v1 = v1 + delta
        self.last_iterations = iterations_total
        x1 = x0 + h * v1
        if not (np.all(np.isfinite(x1)) and np.all(np.isfinite(v1))):
            raise SimulationError("state became non-finite in the implicit step")
        system.x, system.v = x1, v1
        # the next step starts from here unless pins, strain limits or collisions move it
        self._energy = (x1.copy(), v1.copy(), e_end) if e_end is not None and not len(pressed) \
            else None
        return StepReport(steps=1, evaluations=iterations_total, h_last=h)

    def _first_guess(self, shape, t: float):
        """Warm start: the last step's solution extrapolated along the one before (smooth
        motion changes dv smoothly; about 10 % fewer CG iterations than the last alone); a
        step solved again starts from its own last solution."""
        warm = [w for w in self._warm if w.shape == shape]
        if warm and t == self._warm_t:
            return warm[0].copy()
        if len(warm) == 2:
            return 2.0 * warm[0] - warm[1]
        return warm[0].copy() if warm else None

    def _known_energy(self, x: np.ndarray, v: np.ndarray):
        """The energy computed at the end of the last step if the state is still exactly that
        one (else None). It only decides whether a step needs more Newton iterations; a force
        that changed between the steps (keyed gravity) makes that decision from a slightly
        stale start, never the step itself."""
        if self._energy is None:
            return None
        x1, v1, e = self._energy
        return e if np.array_equal(x1, x) and np.array_equal(v1, v) else None

    def _assemble(self, blocks, mass, h):
        """A = M - h df/dv - h^2 df/dx on the pattern of these blocks' cliques (built on first
        use and kept while the blocks couple the same fixed index arrays)."""
        cliques = [blk.clique for blk in blocks if blk.clique is not None]
        if (self._pattern is None or len(self._pattern[0]) != len(cliques)
                or any(a is not b for a, b in zip(self._pattern[0], cliques))
                or self._pattern[1].n != len(mass)):
            pattern = BlockPattern(len(mass), cliques)
            hierarchy = None
            if self.preconditioner == "MULTIGRID":
                # aggregate along springs (pair cliques), the strong couplings
                pairs = [c for c in cliques if c.shape[1] == 2]
                graph = BlockPattern(len(mass), pairs).neighbours if pairs else None
                hierarchy = AggregationHierarchy(pattern, graph)
            self._pattern = (cliques, pattern, hierarchy)
        pattern = self._pattern[1]
        # one buffer for every linearisation: the previous matrix is not used after the next
        # is assembled (each Newton iteration rebuilds its preconditioner)
        builder = MatrixBuilder(pattern, out=pattern.scratch("matrix", (pattern.size,)))
        builder.add_diagonal(np.arange(len(mass)), mass[:, None, None] * np.eye(3))
        for blk in blocks:
            blk.add_to(builder, -h * h, -h)
        return builder.finish()

    @staticmethod
    def _filtered(matrix, free, pressed, normal):
        """The matrix CG really solves with: S A S + (I - S), S removing each vertex's
        constrained directions (all three for a pinned vertex, the normal for a pressed one) —
        what the preconditioner must approximate; a hierarchy built on A itself would move
        constrained vertices with their aggregates and lose most of its power when many are
        constrained (cloth landing on a collider)."""
        constrained = ~free
        constrained[pressed] = True
        if not constrained.any():
            return matrix
        p = matrix.pattern
        s = np.where(free[:, None, None], np.eye(3), 0.0)
        if len(pressed):
            s[pressed] -= normal[:, :, None] * normal[:, None, :]
        # only blocks in a constrained vertex's row or column change
        row, col = np.nonzero(constrained[:, None] | constrained[p.neighbours])
        data = matrix.data.copy()
        blocks = data.reshape(p.n, 3, p.width, 3)
        other = p.neighbours[row, col]
        blocks[row, :, col, :] = np.matmul(np.matmul(s[row], blocks[row, :, col, :]), s[other])
        fixed = np.nonzero(constrained)[0]
        blocks[fixed, :, p.diagonal_slot[fixed] % p.width, :] += np.eye(3) - s[fixed]
        return BlockMatrix(p, data)

    def _preconditioner(self, matrix, free):
        """u -> approximately A^-1 u: one aggregation-multigrid V-cycle (:mod:`.multigrid`;
        iterations barely grow with stiffness), or block Jacobi — the exact inverse 3 x 3
        diagonal blocks (anisotropic: a cloth's springs are stiff only along themselves)."""
        hierarchy = self._pattern[2]
        if hierarchy is not None:
            return hierarchy.preconditioner(matrix)
        a = matrix.diagonal()
        inv = inverse3(np.where(free[:, None, None], a, np.eye(3)))
        inv[~free] = 0.0
        return lambda r: np.matmul(inv, r[:, :, None])[:, :, 0]

    @staticmethod
    def _friction(v1, pressed, normal, contact, reaction, mass) -> np.ndarray:
        """Coulomb friction on pressed vertices: the velocity change (n, 3) that would stop
        each one's sliding, capped by mu times the constraint's normal impulse (the residual of
        the unfiltered system along n)."""
        row = np.searchsorted(contact.index, pressed)  # contact.index is sorted
        mu = contact.friction[row]
        impulse = np.maximum(0.0, np.einsum("ij,ij->i", reaction[pressed], normal))
        rel = v1[pressed] - contact.surface_velocity[row]
        vt = rel - np.einsum("ij,ij->i", rel, normal)[:, None] * normal
        speed = np.sqrt(np.einsum("ij,ij->i", vt, vt))
        stop = np.minimum(speed, mu * impulse / mass[pressed, 0])
        out = np.zeros_like(v1)
        out[pressed] = -(stop / np.where(speed > 1e-12, speed, np.inf))[:, None] * vt
        return out

    def _pcg(self, apply_a, b, precondition, project, start=None, scale=None):
        """Filtered preconditioned conjugate gradients: ``project`` removes the constrained
        directions (pinned vertices, normals of pressed ones). Stops when |r| <= tolerance *
        scale (default |b|)."""
        b_norm = float(np.sqrt(np.vdot(b, b))) if scale is None else scale
        if b_norm == 0.0:
            return np.zeros_like(b), 0, 0.0
        if start is None:
            x = np.zeros_like(b)
            r = b.copy()
        else:
            x = project(start)
            r = b - project(apply_a(x))
        residual = float(np.sqrt(np.vdot(r, r))) / b_norm
        # a warm start gets at least one iteration (an accepted guess would err systematically
        # by up to the tolerance), unless it is exact already
        if residual <= self.tolerance and (start is None or residual == 0.0):
            return x, 0, residual
        z = project(precondition(r))
        p = z.copy()
        rz = float(np.vdot(r, z))
        if rz == 0.0:  # nothing the filter leaves free to correct
            return x, 0, residual
        for it in range(1, self.max_iterations + 1):
            q = project(apply_a(p))
            pq = float(np.vdot(p, q))
            if not (pq > 0.0 and np.isfinite(pq)):
                raise SimulationError("the implicit solve lost positive definiteness "
                                      f"(p.Ap = {pq:.3g}) — lower the stiffness or add substeps")
            alpha = rz / pq
            x += alpha * p
            r -= alpha * q
            residual = float(np.sqrt(np.vdot(r, r))) / b_norm
            if residual <= self.tolerance:
                return x, it, residual
            z = project(precondition(r))
            rz_new = float(np.vdot(r, z))
            p *= rz_new / rz
            p += z
            rz = rz_new
        return x, self.max_iterations, residual
