"""Implicit (backward) Euler for spring meshes, Baraff & Witkin's "Large steps in cloth
simulation" (1998): one linearised step solved by preconditioned conjugate gradients on the
spring Jacobians, with pinned vertices handled by filtering (their velocity change is given).

    (M - h df/dv - h^2 df/dx) dv = h (f0 + h df/dx v0),   v1 = v0 + dv,   x1 = x0 + h v1

The matrix is symmetric (spring Jacobians with the compressed-spring term clamped are
symmetric negative semi-definite), so CG applies: the integrators' projected preconditioned CG
(:func:`~physanim.core.integrators.krylov.projected_pcg`). The matrix is assembled once per
linearisation into a block-sparse pattern built from the topology on the first step
(:mod:`.sparse`), so each CG product is one gather and one batched matrix product; the
preconditioner is aggregation multigrid (:mod:`.multigrid`: iterations barely grow with
stiffness) or block Jacobi, and the first guess extrapolates the previous steps' dv. As in
Baraff & Witkin, the solve is inexact: CG stops at the tolerance or the iteration cap; when the
step gained energy, further Newton iterations re-linearise at its end. Every CG iterate
lowers the A-norm of the error, so a capped solve is still a damped, stable step; only a loss
of positive definiteness or a non-finite value is an error.

:class:`BaraffWitkin` is an :class:`~physanim.core.integrators.Integrator`: the base class
reads the flat state ``[x, v]``, checks the new one is finite and writes it back.
"""
from __future__ import annotations

import numpy as np

from ..integrators import Integrator, StepReport
from ..integrators.krylov import galerkin_start, projected_pcg
from ..transforms import inverse3, scale_rows
from .contact_friction import beyond_cone, contact_filter, kinetic_stop, on_bodies, released
from .implicit_parts import (BaraffWitkinSystem, BlockJacobi, Linearisation, MatrixFree,
                             NewtonResult, SolvePattern, StepMemory, VelocityFilter,
                             filtered_matrix, loosened,
                             positions_and_velocities)
from .multigrid import AggregationHierarchy
from .sparse import BlockMatrix, BlockPattern, MatrixBuilder


class BaraffWitkin(Integrator):
    """Implicit Euler stepper for a :class:`BaraffWitkinSystem`, with the entry point of every
    integrator: ``step(system, t, h)``.

    Args:
        tolerance: relative residual at which CG stops (None: the class's TOLERANCE).
            max_iterations: CG cap.
        newton_iterations: linearisations per step at most (the first is Baraff & Witkin's).
        preconditioner: one of :attr:`PRECONDITIONERS`.
    """

    name = "IMPLICIT"
    # 14 work vectors (n, 3), half the state each: f0, the given dv, dv, rhs, b, the first
    # guess, the reaction, CG's x, r, z, p, q and the two remembered solutions. The assembled
    # matrix comes on top: 9 values per stored block, about 13 blocks per vertex of a cloth
    # with bending (~20 states), twice while a filtered copy exists.
    stages = 7
    stable_h_omega = None  # unconditionally stable

    # relative residual at which CG stops: Baraff & Witkin's inexact solve, as Blender's cloth
    # solver stops (1e-2). Implicit Euler is first order: its own error at a frame's sub-step
    # is mostly far larger than what a solve to a hundredth adds (a swinging sheet at 2e3 /
    # 1e5 / 1e6 N/m: 0.4 / 14 / 68 mm off the exactly solved path, which is 600 / 1,150 / 98
    # mm off 16 sub-steps': alike only for the stiffest), and every implicit Euler accuracy
    # test holds at it; the pinned, draped and
    # self-colliding cloth benchmarks take 13-23 % less time than at 1e-3. Second-order BDF2
    # keeps 1e-3 (its order needs it: :class:`~.bdf2.BDF2`).
    TOLERANCE = 1e-2
    # A step "gains energy" (and is re-linearised) only beyond what rounding makes of a mesh at
    # rest: the kinetic energy of its whole mass at this speed [m/s] (a cloth lying on the
    # ground gained 1e-13 J at random in half its steps, each costing a second solve), or
    # this fraction of the energy's own size.
    ENERGY_SPEED = 1e-5
    ENERGY_ROUNDING = 1e-12
    LINE_SEARCH = 4  # halvings of a Newton correction that raises the step's end energy
    WARM_HISTORY = 3  # earlier steps' solutions the first guess is combined from
    # A pressed vertex sliding slower than this [m/s] is taken as held by static friction (and
    # let slide when the impulse that holds it leaves the friction cone): a cloth at rest on a
    # collider then has nothing left to solve, where each step solved its tiny in-plane
    # forces only for friction to cancel the motion again
    STICK_SPEED = 3e-3
    # Contacts with bodies (two-way coupled) only push. A vertex pressed on one whose contact
    # impulse pulls it onto the surface by more than this share of the step's largest push
    # leaves it (the step is solved again without it): held, it would drag and spin the body.
    # Smaller pulls are the inexact solve's rounding. Other colliders hold pressed vertices as
    # Baraff & Witkin's filter does: loads that act outside the solve (their corners and creases
    # on the mesh's faces, the mesh's own layers on each other) press there too, so the solve's
    # impulse alone does not tell a pull (let go, a cloth slid off a faceted sphere).
    PULL_SHARE = 0.05
    RELEASE_ROUNDS = 3  # re-solves a step may take for that (the first also for slipping ones;
    # slips alone are let go in the friction pass, _step_impl)
    FRICTION_SHARE = 0.1  # the friction solve's residual at most this share of its impulses

    PRECONDITIONERS = ("MULTIGRID", "JACOBI")

    def __init__(self, tolerance: float | None = None, max_iterations: int = 200,
                 newton_iterations: int = 4, preconditioner: str = "MULTIGRID"):
        if preconditioner not in self.PRECONDITIONERS:
            raise ValueError(f"preconditioner must be one of {self.PRECONDITIONERS} "
                             f"(got {preconditioner!r})")
        self.preconditioner = preconditioner
        self.tolerance = float(self.TOLERANCE if tolerance is None else tolerance)
        self.max_iterations = int(max_iterations)
        # A second Newton iteration re-linearises at the end of the step when Baraff & Witkin's
        # single linearisation gained energy (stiff springs rotating within one large step).
        self.newton_iterations = int(newton_iterations)
        self._memory = StepMemory()
        # the matrix structure of the mesh, built on the first step from its Jacobians' cliques
        self._pattern: SolvePattern | None = None
        #: what the last step's solves did: relative residual, CG iterations
        self.last_residual = 0.0
        self.last_iterations = 0
        #: the last step's final linear system, filter and residual floor (:meth:`response`)
        self.last_solve: tuple | None = None

    def _step_impl(self, system: BaraffWitkinSystem, t: float, y: np.ndarray, h: float):
        """forces -> constraints (the filter) -> Newton iterations (linearise -> assemble ->
        precondition -> first guess -> solve -> energy check) -> friction -> the new state."""
        x0, v0 = positions_and_velocities(y)
        # backward Euler's forces are those at the step's end, t + h: the linearisation is
        # about (x0, v0) at that time, so anchors and targets that move during the step
        # (virtual springs, attachments' springs, gusting winds) pull from where they are at
        # its end, as pins are held there (at t they lagged a step behind a moving target)
        f0 = system.forces_at(t + h, x0, v0)
        constraints = self._constraints(system, t, h, v0, f0)
        # residuals are judged against the impulse gravity gives in one step (at least): near
        # equilibrium the right-hand side -> 0 and a purely relative test never stops
        floor = h * float(system.weight_norm())
        newton = self._newton(system, t, h, x0, v0, f0, constraints, floor)
        slipping, leaving = np.zeros(0, np.int64), np.zeros(0, np.int64)
        beyond = None  # the holding impulses static friction cannot give (see below)
        for round_ in range(self.RELEASE_ROUNDS):
            if not len(constraints.pressed):
                break
            more = released(constraints, newton.reaction, system.bodies, self.PULL_SHARE)
            if round_:  # static friction is checked once (on a curved mesh some vertex
                more = (more[0][:0], more[1])  # always slips)
            if not (len(more[0]) or len(more[1])):
                break
            if not len(more[1]) and not on_bodies(constraints, system.bodies):
                # only slips: their holding impulses are cut back to the friction cone's edge
                # (what they keep is kinetic friction, against the way the rest pushes them)
                # and the rest let go in the friction pass, one solve for both, with them free
                # to slide. (A second solve for them, then the friction pass, took a tenth of
                # a cloth's drape over Suzanne, where some vertex slips in half the steps.)
                # Not where vertices press on two-way coupled bodies: a slip can turn another
                # contact there into a pull, which the step solved again finds (next round).
                beyond = beyond_cone(constraints, newton.residual, more[0])
                constraints = self._constraints(system, t, h, v0, f0, more[0])
                newton.last = self._loosened(system, h, newton, constraints, more[0])
                break
            # solved again: they slide, or leave the body (which may load others)
            slipping, leaving = np.union1d(slipping, more[0]), np.union1d(leaving, more[1])
            constraints = self._constraints(system, t, h, v0, f0, slipping, leaving)
            spent = newton.iterations
            first = loosened(newton.first, constraints, np.union1d(*more))
            newton = self._newton(system, t, h, x0, v0, f0, constraints, floor, first)
            newton.iterations += spent
        v1, iterations = v0 + newton.dv, newton.iterations
        residual = newton.residual
        if len(constraints.pressed):
            v1, more, friction = self._apply_friction(system, v1, constraints, newton, floor,
                                                      beyond)
            iterations += more
            residual = residual + friction
        self.last_iterations = iterations
        self.last_solve = (newton.last, constraints, floor, residual)
        x1 = x0 + h * v1
        # the next step starts from here unless pins, strain limits or collisions move it
        self._memory.end = (x1.copy(), v1.copy(), newton.energy) \
            if newton.energy is not None and not len(constraints.pressed) else None
        report = StepReport(steps=1, evaluations=iterations, h_last=h)
        return np.concatenate([x1.ravel(), v1.ravel()]), report

    def residual(self) -> np.ndarray:
        """(n, 3) [N s] the last step's impulses from outside the mesh's own forces: with its
        last linearisation's forces f, M dv = h f + residual. On pinned rows the pins' impulses,
        on pressed rows the colliders' (normal and friction), elsewhere the solve's error. The
        mesh's internal forces cancel in any sum over vertices, so the sum of the residual is
        the momentum change less h times the external forces: the impulses two-way coupling
        hands to bodies, exactly (:mod:`.attach`)."""
        return self.last_solve[3]

    def response(self, given: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """How the last step's velocity change responds, to first order, when its pinned
        vertices' velocity changes by ``given`` (n, 3) (zero rows elsewhere): the change of dv
        (n, 3) — ``given`` on the pinned rows, the free rows solved with the step's matrix and
        filter — and the change of the step's residual A dv - rhs (n, 3), which on the pinned
        rows is the change of the impulses that hold them [N s]. Two-way attachments use it
        to move a body the mesh hangs on implicitly (:mod:`.attach`)."""
        linear, constraints, floor, _ = self.last_solve
        b = constraints.project(-linear.apply_a(given))
        scale = max(float(np.sqrt(np.sum(b * b))), floor)
        delta, _, _ = projected_pcg(linear.apply_a, b, linear.precondition, constraints.project,
                                    self.tolerance, self.max_iterations, None, scale)
        dv = given + delta
        return dv, linear.apply_a(dv)

    # --- the passes of a step ------------------------------------------------------------------
    @classmethod
    def _constraints(cls, system: BaraffWitkinSystem, t: float, h: float, v0: np.ndarray,
                     f0: np.ndarray, slipping: np.ndarray | None = None,
                     leaving: np.ndarray | None = None) -> VelocityFilter:
        """The step's filter: pins, and contacts where ``f0`` presses, vertices slower than
        STICK_SPEED held by static friction (:func:`.contact_friction.contact_filter`)."""
        return contact_filter(system, t, h, v0, f0, cls.STICK_SPEED, slipping, leaving)

    def _newton(self, system: BaraffWitkinSystem, t: float, h: float, x0: np.ndarray,
                v0: np.ndarray, f0: np.ndarray, constraints: VelocityFilter,
                floor: float, first_linear: tuple | None = None) -> NewtonResult:
        """Baraff & Witkin's linearised step, then, while the step gains energy, Newton
        iterations that re-linearise at its end: linearise -> assemble and precondition ->
        first guess -> solve. ``first_linear``: the step's first linearisation from an earlier
        solve of it (:attr:`NewtonResult.first`) whose constraints were these or tighter: its
        preconditioner serves too (see :meth:`_linear_system`), the filter is new."""
        e0 = self._start_energy(system, x0, v0)
        slack = 0.5 * float(system.mass[system.free].sum()) * self.ENERGY_SPEED ** 2 + \
            self.ENERGY_ROUNDING * abs(e0)
        out = NewtonResult(dv=constraints.given.copy())
        e_end = None  # the energy at the end of the step out.dv makes, once known
        for newton in range(self.newton_iterations):
            first = newton == 0
            if not first:
                if e_end is None:
                    e_end = system.energy(x0 + h * (v0 + out.dv), v0 + out.dv)
                if e_end <= e0 + slack:
                    out.energy = e_end  # the step already lost energy: no need to re-linearise
                    break
                rhs = self._newton_rhs(system, t, h, x0, v0, out.dv)
                b = constraints.project(rhs.copy())
                if np.vdot(b, b) <= (self.tolerance * floor) ** 2:
                    # the step's end solves the implicit equations within the tolerance
                    # already: a linearisation there would only confirm it (its solve takes
                    # no iteration), and so would the next ones
                    out.residual, out.energy = -rhs, e_end
                    break
            matrix = precondition = None
            if first and first_linear is not None:
                blocks, rhs, matrix, precondition = first_linear
            elif first:
                blocks, rhs = self._linearize(system, t + h, h, x0, v0, f0)
            else:  # Newton: linearised at the step's end
                blocks = system.linearize(t + h, x0 + h * (v0 + out.dv), v0 + out.dv)
                kept = out.first[2]
                if kept is not None:  # the assembly below overwrites its buffer: keep a copy
                    out.first = (*out.first[:2], BlockMatrix(kept.pattern, kept.data.copy()),
                                 out.first[3])
            linear = self._linear_system(system, h, blocks, rhs, constraints, matrix,
                                         precondition)
            if first:
                out.first = (blocks, rhs, linear.matrix,
                             linear.precondition if linear.matrix is not None else None)
            known = out.dv if first else np.zeros_like(out.dv)
            guess = self._first_guess(out.dv.shape, t) if first else None
            start = None if guess is None else [g - known for g in guess]  # (guesses of dv)
            delta, iterations, residual, scale = self._solve(linear, known, constraints, start,
                                                             floor)
            out.scale = max(out.scale, scale)
            out.iterations += iterations
            stop = False
            if not first:
                delta, e_end = self._line_search(system, h, x0, v0, out.dv, delta, e_end)
                # no share of the correction lowers the energy: the step stays where it is
                # (linearised there: this iteration's matrix and residual serve what follows)
                stop = delta is None
                if stop:
                    delta = np.zeros_like(out.dv)
            out.residual = linear.apply_a(delta + known) - rhs  # the constraints' impulses
            if first:
                self._remember_solution(delta + known, t, not len(constraints.pressed))
                out.reaction = out.residual
            out.dv = out.dv + delta
            out.last = linear
            self.last_residual = residual
            if stop:
                break
        return out

    def _line_search(self, system: BaraffWitkinSystem, h: float, x0: np.ndarray,
                     v0: np.ndarray, dv: np.ndarray, delta: np.ndarray, e_end: float):
        """A Newton correction ``delta`` of the step's velocity change ``dv``, halved until it
        lowers the energy at the step's end below ``e_end``, where ``dv`` leaves it (the
        iterations run to stop a step gaining energy): ``(delta, its end energy)``, or
        ``(None, e_end)`` when LINE_SEARCH halvings do not. Far from the solution a full
        correction can overshoot: a cloth landing on its edge, a row of triangles squashed
        flat, had its second correction end the step at 3,800 J from 11 J, the next at 9 J."""
        for _ in range(self.LINE_SEARCH):
            trial = dv + delta
            e_trial = system.energy(x0 + h * (v0 + trial), v0 + trial)
            if e_trial < e_end:
                return delta, e_trial
            delta = 0.5 * delta
        return None, e_end

    @staticmethod
    def _linearize(system: BaraffWitkinSystem, t: float, h: float, x0: np.ndarray,
                   v0: np.ndarray, f0: np.ndarray):
        """Jacobian blocks and right-hand side (n, 3) [N s] of the first Newton iteration,
        Baraff & Witkin's: linearised at (x0, v0) and time ``t`` (the step's end), rhs
        h (f0 + h df/dx v0)."""
        blocks = system.linearize(t, x0, v0)
        rhs = f0.copy()
        for blk in blocks:
            blk.product(h, 0.0, v0, rhs)
        rhs *= h
        return blocks, rhs

    @staticmethod
    def _newton_rhs(system: BaraffWitkinSystem, t: float, h: float, x0: np.ndarray,
                    v0: np.ndarray, dv: np.ndarray) -> np.ndarray:
        """-g(dv) (n, 3) [N s] for Newton on g(dv) = M dv - h f(x0 + h (v0 + dv), v0 + dv):
        the right-hand side of a later Newton iteration."""
        v1 = v0 + dv
        return h * system.forces_at(t + h, x0 + h * v1, v1) - scale_rows(dv, system.mass)

    def _linear_system(self, system: BaraffWitkinSystem, h: float, blocks: list,
                       rhs: np.ndarray, constraints: VelocityFilter,
                       matrix: BlockMatrix | None = None,
                       precondition=None) -> Linearisation:
        """Assemble A (unless ``matrix`` is these blocks' already) and its preconditioner —
        rebuilt for every linearisation: a stiff mesh turning within the step changes its
        matrix enough that the first one's preconditioner would cost hundreds of iterations in
        the later Newton iterations. ``precondition``: the preconditioner of this matrix
        filtered with tighter constraints (a step solved again with vertices let slide or
        leave, or its friction pass letting slipping ones go), its finest blocks at those vertices made the looser filter's
        (:func:`~.implicit_parts.loosened`): an SPD operator on all of the space, so CG
        projected onto the looser filter's directions converges with it as well, none of the
        filtering and multigrid set-up (a quarter of such a re-solve's time)."""
        sliding, free = constraints.sliding, constraints.free
        if not free.any():  # every vertex pinned or stuck: dv is given, only products remain
            # (and the filter leaves nothing to precondition)
            return Linearisation(rhs, MatrixFree(blocks, system.mass, h), np.zeros_like)
        if matrix is None:
            matrix = self._assemble(blocks, system.mass, h)
        if precondition is not None:
            return Linearisation(rhs, matrix.__matmul__, precondition, matrix)
        filtered = self._filtered(matrix, free, constraints.pressed[sliding],
                                  constraints.normal[sliding], constraints.diagonal)
        return Linearisation(rhs, matrix.__matmul__, self._preconditioner(filtered, free),
                             matrix)

    def _loosened(self, system: BaraffWitkinSystem, h: float, newton: NewtonResult,
                  constraints: VelocityFilter, freed: np.ndarray) -> Linearisation:
        """The step's last linearisation for the looser ``constraints`` that let the vertices
        ``freed`` slide (the friction pass's): its preconditioner's blocks there made
        theirs (:func:`loosened`; an SPD operator on the whole space, see :meth:`_linear_system`),
        or, when the solve held every vertex (nothing to precondition, no matrix), the first
        linearisation's matrix and a preconditioner built for them."""
        last = newton.last
        if last.matrix is None:
            blocks, rhs = newton.first[:2]
            return self._linear_system(system, h, blocks, rhs, constraints)
        kept = loosened((None, last.rhs, last.matrix, last.precondition), constraints, freed)
        return Linearisation(last.rhs, last.apply_a, kept[3], last.matrix)

    def _solve(self, linear: Linearisation, known: np.ndarray, constraints: VelocityFilter,
               start: np.ndarray | None, floor: float):
        """The correction to dv that solves ``linear`` given its ``known`` part (n, 3):
        ``(delta, iterations, relative residual, the size of the right-hand side the residual
        is relative to)``."""
        b = constraints.project(linear.rhs - (linear.apply_a(known) if np.any(known) else 0.0))
        scale = max(float(np.sqrt(np.sum(b * b))), floor)
        product = None  # project(A start), where known
        if start is not None and len(start) > 1:
            start, product = galerkin_start(linear.apply_a, b, constraints.project, start)
        elif start is not None:
            start = start[0]
        return (*projected_pcg(linear.apply_a, b, linear.precondition, constraints.project,
                               self.tolerance, self.max_iterations, start, scale, product),
                scale)

    def _apply_friction(self, system: BaraffWitkinSystem, v1: np.ndarray,
                        constraints: VelocityFilter, newton: NewtonResult, floor: float,
                        beyond: np.ndarray | None = None) -> tuple[np.ndarray, int]:
        """Coulomb friction is an impulse on the pressed vertices; the mesh takes it as a whole
        (one more filtered solve, with the last linearisation), so a vertex that friction slows
        drags its neighbours along instead of stretching the springs to them. The correction is
        solved to the step's own accuracy (the tolerance times the step's right-hand side), not
        to the tolerance times its own size: the step is only as exact as its main solve, and friction's
        small impulses solved that finely took a quarter of a draped cloth's iterations; but
        never coarser than FRICTION_SHARE of its own impulses, or it would be dropped whole.
        ``beyond``: (n, 3) [N s] holding impulses static friction was found not to give (on
        vertices ``constraints`` let slide, stuck in the solve), let go in the same solve.
        Returns the new velocities (n, 3) [m/s], the CG iterations spent and the impulses
        (n, 3) [N s] the step's residual gains (friction's on the pressed vertices)."""
        mass = system.mass[:, None]
        stop = kinetic_stop(v1, constraints, newton.reaction, mass)
        if not np.any(stop) and beyond is None:
            return v1, 0, 0.0
        b = mass * stop if beyond is None else mass * stop - beyond
        b = constraints.project(b)
        size = float(np.sqrt(np.vdot(b, b)))
        # (a towel lying in folds, its springs' forces large, slid across the floor at 10 cm/s
        # while its friction, within the step's tolerance, took no CG iteration)
        scale = min(max(size, newton.scale, floor), self.FRICTION_SHARE * size / self.tolerance)
        linear = newton.last
        start = self._memory.friction  # (projected in place by CG: a copy)
        start = start.copy() if start is not None and start.shape == b.shape else None
        delta, iterations, _ = projected_pcg(linear.apply_a, b, linear.precondition,
                                             constraints.project, self.tolerance,
                                             self.max_iterations, start, scale)
        self._memory.friction = delta
        return v1 + delta, iterations, linear.apply_a(delta)

    # --- memory between steps ------------------------------------------------------------------
    def _first_guess(self, shape, t: float) -> list[np.ndarray] | None:
        """Warm start for dv, as guesses for :func:`~physanim.core.integrators.krylov.galerkin_start` to
        combine: the last steps' solutions (up to WARM_HISTORY) while none of them pressed a
        vertex on a collider (smooth motion changes dv smoothly: a hanging cloth swinging took
        6,909 CG iterations over the pinned benchmark from the last solution extrapolated along
        the one before, 5,664 from the best combination of the last three); else the last
        solution alone (a cloth landing on a body does not change smoothly, and combining its
        stops and slips costs more than it saves). A step solved again starts from its own last
        solution."""
        memory = self._memory
        warm = [w for w in memory.warm if w.shape == shape]
        if warm and t == memory.warm_t:
            return [warm[0]]
        if len(warm) >= 2 and all(memory.smooth[:len(warm)]):
            return warm
        return warm[:1] or None

    def _remember_solution(self, dv: np.ndarray, t: float, smooth: bool) -> None:
        """Keep the first solve's dv for the next first guess; a step solved again (landing
        constraints) replaces its own entry. (dv itself, not the solve's correction to what
        the constraints prescribe: a step solved again with vertices landing prescribes more,
        and corrects less, than its first solve.) ``smooth``: no vertex was pressed."""
        memory = self._memory
        again = t == memory.warm_t
        last = self.WARM_HISTORY
        keep = memory.warm[1:last] if again else memory.warm[:last - 1]
        smooth_kept = memory.smooth[1:last] if again else memory.smooth[:last - 1]
        memory.warm, memory.warm_t = [dv.copy()] + keep, t
        memory.smooth = [smooth] + smooth_kept

    def _start_energy(self, system: BaraffWitkinSystem, x: np.ndarray, v: np.ndarray) -> float:
        """The energy at the step's start: the one computed at the end of the last step if the
        state is still exactly that one. It only decides whether a step needs more Newton
        iterations; a force that changed between the steps (keyed gravity) makes that decision
        from a slightly stale start, never the step itself."""
        end = self._memory.end
        if end is not None and np.array_equal(end[0], x) and np.array_equal(end[1], v):
            return end[2]
        return system.energy(x, v)

    # --- the linear system ---------------------------------------------------------------------
    def _solve_pattern(self, blocks, n: int) -> SolvePattern:
        """The pattern of these blocks' cliques: the remembered one while the blocks couple the
        same fixed index arrays, else a new one (with its multigrid hierarchy)."""
        cliques = [blk.clique for blk in blocks if blk.clique is not None]
        known = self._pattern
        if (known is not None and len(known.cliques) == len(cliques)
                and all(a is b for a, b in zip(known.cliques, cliques))
                and known.pattern.n == n):
            return known
        pattern = BlockPattern(n, cliques)
        hierarchy = None
        if self.preconditioner == "MULTIGRID":
            # aggregate along springs (pair cliques), the strong couplings
            pairs = [c for c in cliques if c.shape[1] == 2]
            graph = BlockPattern(n, pairs).neighbours if pairs else None
            hierarchy = AggregationHierarchy(pattern, graph)
        self._pattern = SolvePattern(cliques, pattern, hierarchy)
        return self._pattern

    def _assemble(self, blocks, mass, h):
        """A = M - h df/dv - h^2 df/dx on the pattern of these blocks' cliques."""
        pattern = self._solve_pattern(blocks, len(mass)).pattern
        # one buffer for every linearisation: the previous matrix is not used after the next
        # is assembled (each Newton iteration rebuilds its preconditioner)
        builder = MatrixBuilder(pattern, out=pattern.scratch("matrix", (pattern.size,)))
        builder.add_diagonal(np.arange(len(mass)), mass[:, None, None] * np.eye(3))
        for blk in blocks:
            blk.add_to(builder, -h * h, -h)
        return builder.finish()

    _filtered = staticmethod(filtered_matrix)  # (the matrix CG solves: implicit_parts)

    def _preconditioner(self, matrix, free):
        """u -> approximately A^-1 u: one aggregation-multigrid V-cycle (:mod:`.multigrid`;
        iterations barely grow with stiffness), or block Jacobi — the exact inverse 3 x 3
        diagonal blocks (anisotropic: a cloth's springs are stiff only along themselves)."""
        hierarchy = self._pattern.hierarchy
        if hierarchy is not None:
            return hierarchy.preconditioner(matrix)
        a = matrix.diagonal()
        # (the identity on constrained vertices, not zero: SPD on all of the space, so it
        # serves a looser filter too — their rows are projected out of every use here)
        return BlockJacobi(inverse3(np.where(free[:, None, None], a, np.eye(3))))
