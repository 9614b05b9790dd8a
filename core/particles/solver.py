"""The particle solver: one call advances a State by one frame interval in sub-steps.

Per sub-step, in order (each a named pass below):
    collide   find particles resting on colliders (for the contact force)
    forces    the force list: gravity, force objects, particle springs, contact (last)
    integrate the chosen ODE integrator on the flat state y = [x, v]; hard constraints
              (rigid links, an emitter's planes, spheres and wires) add Witkin's constraint
              forces last in every derivative
    respond   continuous collision response on each particle's path (no tunnelling)
    constrain hard constraints held exactly again (RATTLE after a first-order step, post-
              stabilisation after a higher-order one: :mod:`physanim.core.forces.constraints`)
    check     every value finite, or an error naming emitter, frame and particle
    age/kill  particles whose age reaches their life span die (sub-emitters burst there)
    emit      births of this sub-step, placed at their sub-frame time and advanced to its end;
              a birth whose life span ends before the sub-step does never enters the State and
              dies at its death point, where its sub-emitters burst in this same sub-step

The passes from collide to check leave out the particles at rest: those the last sub-step
left exactly as they were, while the sub-step stays the function it was (:mod:`.rest`).
"""
from __future__ import annotations

import math

from dataclasses import dataclass

import numpy as np

from ..bounds import DEFAULT_BOUNDS, StateBounds
from ..contact import ColliderPaths, ContactForce, respond, resting_contacts
from ..errors import PhysanimError, SimulationError, at_frame
from ..forces import DampedSprings, Gravity, HardConstraints, Rods
from ..integrators import make_integrator
from ..world import SolverSettings, SolverSystem, World, WorldFrame
from .blocks import Looked, in_blocks, separable
from .emit import Births, sample_births, sample_bursts
from .frame_inputs import FrameInputs, FrameReport, ParticleDrive
from .model import ParticleModel, ParticleState
from .ode import ParticleOde
from .point_rows import point_rows
from .rest import Conditions, Rest, conditions
from .ties import TIE, TieFrame

FIRST_ORDER = ("EULER", "SYMPLECTIC_EULER", "IMPLICIT")  # integrators whose rods take RATTLE
MAX_PARTICLES = 50_000_000  # hard limit that keeps a bake inside memory (~5 GB of state)
_NONE = np.zeros(0, np.int64)  # no particle (read only)
_NONE.flags.writeable = False
_NO_DEATHS = (np.zeros((0, 3)), np.zeros((0, 3)))  # an emitter's dead (x, v) in a sub-step
for _a in _NO_DEATHS:
    _a.flags.writeable = False


@dataclass
class _FrameStep:
    """One frame interval of a particle state in progress (between begin and end of frame)."""

    state: ParticleState
    inputs: FrameInputs
    paths: list  # the colliders' paths over the interval
    h: float  # sub-step [s]
    g: np.ndarray  # gravity (3,) [m/s^2]
    rest_speed: float  # [m/s] a bounce slower than this ends in contact
    births: list  # per emitter, this frame's Births (sub-emitters burst during the sub-steps)
    report: FrameReport
    ties: TieFrame | None = None  # particles tied to objects (None: no tie this frame)
    rest: Conditions | None = None  # what its sub-steps are a function of (:mod:`.rest`)
    blocks: bool = False  # whether its particles move on their own, in blocks (:mod:`.blocks`)
    gravity: Gravity | None = None  # the force of g (None without gravity)

    @property
    def reactions(self) -> list:
        """What the ties did to rigid bodies this frame (:class:`~..world.Reaction`)."""
        return self.ties.frame_reactions() if self.ties is not None else []


class ParticleSystem(SolverSystem):
    """A particle state and its solver as one system of a :class:`~physanim.core.world.World`;
    its own per-frame input is a :class:`ParticleDrive`."""

    def __init__(self, solver: ParticleSolver, state: ParticleState, name: str = "particles"):
        super().__init__(solver, state, name)

    def inputs(self, frame: WorldFrame, drive: ParticleDrive) -> FrameInputs:
        return FrameInputs.of(frame, drive)

    def report(self, step: _FrameStep) -> FrameReport:
        step.report.alive = self.state.particle_count
        step.report.at_rest = self.solver.at_rest
        return step.report


def _scatter(full: np.ndarray, rows: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``full`` with ``values`` at ``rows`` (in place where it is writable)."""
    if not full.flags.writeable:
        full = full.copy()
    full[rows] = values
    return full


def _up(g: np.ndarray) -> np.ndarray | None:
    """The unit vector against gravity ``g`` (None when there is none)."""
    length = float(np.linalg.norm(g))
    return -g / length if length > 0.0 else None


class ParticleSolver:
    """Advances a :class:`ParticleState` of a :class:`ParticleModel` frame by frame.

    Args:
        model: the frozen model.
        integrator: an integrator name of :data:`physanim.core.integrators.INTEGRATORS`.
        substeps: sub-steps per frame (>= 1).
        tolerance: error tolerance of the adaptive integrator.
        bounds: a particle beyond them (position or speed) stops the bake with an error.
        colliders: makes each frame's collider paths and keeps what lasts between frames (a
            caller baking several systems passes one to all of them; default: a new one).
    """

    def __init__(self, model: ParticleModel, integrator: str = "SYMPLECTIC_EULER",
                 substeps: int = 1, tolerance: float = 1e-4, bounds: StateBounds = DEFAULT_BOUNDS,
                 colliders: ColliderPaths | None = None):
        self.settings = SolverSettings(integrator, substeps, tolerance, bounds)
        self.model = model
        self.bounds = bounds
        self.integrator = make_integrator(integrator, tolerance)
        self.substeps = self.settings.substeps
        self.colliders = ColliderPaths() if colliders is None else colliders
        self._rest = Rest()  # the particles at rest, which sub-steps skip

    def __setstate__(self, saved: dict) -> None:
        """A solver saved before particles at rest were skipped resumes with none at rest."""
        self.__dict__.update({"_rest": Rest(), **saved})

    @property
    def at_rest(self) -> int:
        """How many particles the next sub-step skips, at rest (:mod:`.rest`)."""
        return self._rest.count

    # -- the frame ------------------------------------------------------------------------------
    def advance(self, state: ParticleState, inputs: FrameInputs) -> FrameReport:
        """Advance ``state`` (in place) from ``inputs.t0`` to ``inputs.t0 + inputs.frame_dt``:
        a world of this one system."""
        system = ParticleSystem(self, state)
        world = World([system], self.colliders)
        return world.advance(inputs.world, {system: inputs.drive}).reports[system]

    def begin_frame(self, state: ParticleState, inputs: FrameInputs, paths: list) -> _FrameStep:
        """Check the interval's emitter inputs and sample its births (one draw per frame)."""
        model = self.model
        if len(inputs.emitters) != model.emitter_count:
            raise ValueError(f"frame {inputs.frame}: {len(inputs.emitters)} emitter inputs for "
                             f"{model.emitter_count} emitters")
        for e, ef in zip(model.emitters, inputs.emitters):
            try:
                ef.validated(e.name)
            except ValueError as exc:
                detail = str(exc).removeprefix(f'emitter "{e.name}": ')
                raise PhysanimError(detail, obj=e.name, frame=inputs.frame, kind="emitter") from exc
        h = inputs.frame_dt / self.substeps
        self._check_stiffness(state, inputs, h)
        gravity = tuple(float(c) for c in inputs.gravity)
        g = np.array(gravity)
        tied = any(c.kind == TIE for ef in inputs.emitters for c in ef.constraints)
        ties = TieFrame(inputs, h) if tied else None
        if ties is not None and ties.coupled and self.settings.integrator != "SYMPLECTIC_EULER":
            name, body = next(iter(ties.coupled.items()))
            raise PhysanimError(
                f'ties the particles to the rigid body "{body}", which needs the Symplectic '
                f"Euler integrator (the scene's is {self.settings.integrator}) — choose it in "
                "the scene's PhysAnim settings", obj=name, frame=inputs.frame, kind="constraint")
        alone = ties is None and not len(state.link_a) and \
            not any(ef.constraints for ef in inputs.emitters) and \
            all(e.link is None for e in model.emitters)  # (springs may be born mid-frame)
        return _FrameStep(state, inputs, paths, h, g, 2.0 * math.hypot(*gravity) * h + 1e-4,
                          [self._sample(state, inputs, i) for i in range(model.emitter_count)],
                          FrameReport(per_emitter_births=[0] * model.emitter_count), ties,
                          conditions(self.settings.integrator, g, h, inputs, paths, alone),
                          separable(self.settings.integrator, alone, inputs),
                          Gravity(gravity) if any(gravity) else None)

    @staticmethod
    def _check_stiffness(state: ParticleState, inputs: FrameInputs, h: float) -> None:
        """An interaction too stiff for the sub-step (its particles' lightest) stops the bake
        up front, saying how many sub-steps it needs, instead of blowing up frames later."""
        for spec in (*inputs.interactions, *inputs.collisions):
            members = spec.emitters or range(len(inputs.emitters))
            masses = [ef.mass for e, ef in enumerate(inputs.emitters)
                      if e in members and ef.active]
            held = state.particle_mass[np.isin(state.particle_emitter, list(members))]
            if len(held):
                masses.append(float(held.min()))
            if not masses:
                continue
            longest = spec.max_step(min(masses))
            if h > longest:
                need = math.ceil(inputs.frame_dt / longest)
                raise PhysanimError(
                    f"too stiff for sub-steps of {1000 * h:.3g} ms on {min(masses):g} kg "
                    f"particles: it needs {1000 * longest:.3g} ms or less — raise the scene's "
                    f"Substeps to {need}, or lower its Epsilon", obj=spec.name,
                    frame=inputs.frame, kind="force")

    def substep(self, step: _FrameStep, k: int) -> None:
        """Sub-step ``k`` of the interval: the passes of the module docstring, the moving ones
        over the particles not at rest (:mod:`.rest`)."""
        state, inputs, h = step.state, step.inputs, step.h
        s0, s1 = k / self.substeps, (k + 1) / self.substeps
        t = inputs.t0 + k * h
        awake = self._rest.awake(state, step.rest)
        tied = ([], None)  # (a sub-step with particles at rest has no ties)
        checked = 0  # the particles (from the first) the move found within the bounds
        if awake is None:
            look = Looked(state.particle_count, step.rest, self.bounds)
            x0, v0, tied = in_blocks(self._move, step, state, s0, s1, t, look)
            self._rest.rested(state, None, look.still, step.rest)
            # (separable: nothing but deaths and births changes them before the check)
            checked = state.particle_count if look.inside and step.blocks else 0
        elif len(awake):
            moving = state.subset(awake)
            x0, v0, _ = self._move(step, moving, s0, s1, t)
            state.particle_x, state.particle_v = (
                _scatter(state.particle_x, awake, moving.particle_x),
                _scatter(state.particle_v, awake, moving.particle_v))
            self._rest.settle(state, awake, x0, v0, moving.particle_x, moving.particle_v,
                              step.rest)
        else:  # every particle at rest: the step leaves them as they are
            step.report.integrator_steps += 1
        deaths, died = self._age_kill(state, h, inputs)
        step.report.deaths += died
        checked -= died
        alive = state.particle_count
        self._emit(state, inputs, step.births, deaths, s0, s1, step.g, step.report)
        self._rest.born(state.particle_count - alive)
        if state.particle_count > alive and any(ef.constraints for ef in inputs.emitters):
            born = self._constraints(state, inputs, s1, t + h, h, tied)
            if born is not None:  # the newborn onto them
                self._constrain(state, born, None, t + h, h)
        # the particles at rest are as they were when last checked
        self._check_bounds(state, inputs, (None if not checked else slice(checked, None))
                           if awake is None else np.flatnonzero(~self._rest.mask))
        state.t = t + h

    def _move(self, step: _FrameStep, state: ParticleState, s0: float, s1: float,
              t: float, into: tuple | None = None) -> tuple[np.ndarray, np.ndarray, tuple]:
        """The passes that move the particles of ``state`` (the frame's, or those of it not at
        rest), from collide to check; returns their positions and velocities before, and the
        sub-step's ties (:meth:`TieFrame.substep`). ``into``: (x, v) arrays the integrator
        may write the new state into (:mod:`.blocks`)."""
        inputs, h = step.inputs, step.h
        tied = ([], None) if step.ties is None else step.ties.substep(
            state, inputs.emitters, s0, s1, t, h)
        still = _NONE if not tied[0] and tied[1] is None else np.concatenate(
            [p.i for p in tied[0]] + [_NONE] + ([] if tied[1] is None else [tied[1].i]))
        # (tied: no collider moves them)
        resting = resting_contacts(step.paths, state.particle_x, state.particle_v, s0,
                                   step.rest_speed)
        contact = ContactForce(resting.take(~np.isin(resting.index, still)) if len(still)
                               else resting, h)
        x0, v0 = state.particle_x, state.particle_v
        held = self._constraints(state, inputs, s0, t, h, tied)
        with at_frame(inputs.frame):  # an interaction's failure knows no frame
            step.report.integrator_steps += self._integrate(
                state, self._forces(state, inputs, step.gravity), contact, held, t, h, inputs,
                into)
        if tied[1] is not None:  # the bodies take what the step's tie forces gave them
            tied[1].commit(h)
        done = respond(step.paths, x0, state.particle_x, v0, state.particle_v, s0, s1, h,
                       step.rest_speed, own=not len(still))  # (the tied keep their own)
        if len(still):
            done.x[still], done.v[still] = state.particle_x[still], state.particle_v[still]
        state.particle_x, state.particle_v = done.x, done.v
        step.report.collisions += done.count
        if inputs.collisions:
            with at_frame(inputs.frame):
                self._collide_pairs(step, x0, v0, s1, contact.contacts)
        if held is not None:
            self._constrain(state, held, x0, t + h, h)
        return x0, v0, tied  # (non-finite values are named by _check_bounds)

    # -- passes ---------------------------------------------------------------------------------
    def _collide_pairs(self, step: _FrameStep, x0, v0, s1: float, resting) -> None:
        """Particles against each other (:mod:`.pair_collisions`), then against the colliders
        again: a push from a neighbour must not carry a particle into the ground."""
        state, h = step.state, step.h
        for spec in step.inputs.collisions:
            before = state.particle_x
            x, v, count, warm = spec.resolve(
                state.particle_x, state.particle_v, x0, v0, state.particle_size,
                state.particle_mass, state.particle_emitter, h, step.rest_speed,
                (resting.index, resting.normal, resting.friction,
                 resting.surface_velocity), state.particle_id,
                state.pair_warm.get(spec.name), _up(step.g))
            state.pair_warm[spec.name] = warm
            if not count:
                continue
            step.report.collisions += count
            done = respond(step.paths, before, x, state.particle_v, v, s1, s1, h,
                           step.rest_speed)
            state.particle_x, state.particle_v = done.x, done.v

    def _sample(self, state, inputs, i) -> Births:
        """This frame's births of mesh/origin emitter ``i`` (sub-emitters burst in ``_emit``)."""
        e = self.model.emitters[i]
        if e.source == "DEATHS":
            return Births.empty()
        try:
            return sample_births(state.rngs[i], e, inputs.emitters[i], inputs.frame_dt)
        except PhysanimError:
            raise
        except ValueError as exc:  # e.g. a volume that encloses nothing: name emitter and frame
            raise PhysanimError(str(exc), obj=e.name, frame=inputs.frame, kind="emitter") from exc

    def _forces(self, state, inputs, gravity: Gravity | None) -> list:
        forces: list = [] if gravity is None else [gravity]
        forces.extend(inputs.forces)
        forces.extend(spec.bind(state.particle_emitter) for spec in inputs.interactions)
        if len(state.link_a):
            for e, settings in enumerate(self.model.emitters):
                sel = state.link_emitter == e
                if settings.link is None or settings.link.hard or not sel.any():
                    continue
                forces.append(DampedSprings(state.index_of(state.link_a[sel]),
                                            state.index_of(state.link_b[sel]),
                                            state.link_rest[sel], settings.link.stiffness,
                                            settings.link.damping))
        return forces

    def _constraints(self, state, inputs, s0: float, t: float, h: float,
                     tied: tuple = ([], None)) -> HardConstraints | None:
        """The sub-step's hard constraints: the hard links (rods) between living particles,
        the emitters' point constraints (planes, spheres, wires) and the ties (``tied``: pins
        and the ties to rigid bodies, solved with the particles: :meth:`TieFrame.substep`),
        or None."""
        kinds = []
        if len(state.link_a):
            hard = np.array([e.link is not None and e.link.hard for e in self.model.emitters])
            sel = np.nonzero(hard[state.link_emitter])[0]
            # each emitter's links in birth order: a chain's rods side by side, so their
            # system is tridiagonal (solved directly by cyclic reduction)
            sel = sel[np.argsort(state.link_emitter[sel], kind="stable")]
            if len(sel):
                kinds.append(Rods(state.index_of(state.link_a[sel]),
                                  state.index_of(state.link_b[sel]), state.link_rest[sel]))
        for e, ef in enumerate(inputs.emitters):
            held = np.nonzero(state.particle_emitter == e)[0] if ef.constraints else ()
            for c in ef.constraints if len(held) else ():
                if c.kind != TIE:
                    kinds.extend(point_rows(c, held, s0, t, h, inputs.frame_dt))
        kinds.extend(tied[0])
        return HardConstraints(kinds, bodies=tied[1]) if kinds or tied[1] else None

    def _constrain(self, state, held: HardConstraints, x0, t, h) -> None:
        """The particles back on their constraints: after a first-order step along the
        gradients of its start ``x0`` (RATTLE: bounded energy error), after a higher-order one
        (or with ``x0`` None: newborn particles) along their own."""
        first_order = self.settings.integrator in FIRST_ORDER
        x, v = state.particle_x.copy(), state.particle_v.copy()
        rattle = first_order and x0 is not None and len(x0) == len(x)
        held.project(x, v, t, 1.0 / state.particle_mass, start=x0 if rattle else None, h=h)
        state.particle_x, state.particle_v = x, v
        if held.bodies is not None:
            held.bodies.finish(x)

    def _integrate(self, state, forces, contact, rods, t, h, inputs, into=None) -> int:
        if state.particle_count == 0:
            return 0
        ode = ParticleOde(state, forces, contact, rods, into)
        try:
            return self.integrator.step(ode, t, h).steps
        except SimulationError as exc:
            # The integrator left the state as it was: take one Euler trial step to find the
            # particles whose values go non-finite, and name them.
            n = state.particle_count
            with np.errstate(all="ignore"):
                y = ode.get_state()
                trial = y + h * ode.derivative(t, y)
            x, v = trial[:3 * n].reshape(n, 3), trial[3 * n:].reshape(n, 3)
            raise self._blame(state, inputs, str(exc), x, v) from exc

    def _check_bounds(self, state, inputs, rows: np.ndarray | slice | None = None) -> None:
        """Every particle (or those at ``rows``: indices or a slice) finite and within the
        bounds, or an error naming one (a non-finite value as a blow-up: :meth:`_blame`)."""
        x, v = state.particle_x, state.particle_v
        bad = self.bounds.violation(x if rows is None else x[rows], v if rows is None else v[rows])
        if bad is not None:
            if not (np.isfinite(x).all() and np.isfinite(v).all()):
                raise self._blame(state, inputs, "", x, v)
            i, what = bad
            i = i if rows is None else int(np.arange(len(x))[rows][i])
            raise SimulationError(
                f"particle {int(state.particle_id[i])} {what} — check gravity, forces and "
                "emitter speeds, or raise the limits in Scene > PhysAnim > Limits",
                obj=self.model.emitters[int(state.particle_emitter[i])].name, frame=inputs.frame,
                kind="emitter")

    def _blame(self, state, inputs, detail, x, v) -> SimulationError:
        """An error naming the emitter, frame, particle and value that went wrong."""
        with np.errstate(all="ignore"):
            bad = ~(np.isfinite(x).all(axis=1) & np.isfinite(v).all(axis=1))
            if not bad.any():  # nothing non-finite yet: blame the fastest particle
                bad = np.linalg.norm(v, axis=1) >= np.linalg.norm(v, axis=1).max()
        i = int(np.argmax(bad))
        emitter = self.model.emitters[int(state.particle_emitter[i])].name
        what, value = ("velocity", v[i]) if not np.isfinite(v[i]).all() or np.isfinite(x[i]).all() \
            else ("position", x[i])
        msg = (f"particle {int(state.particle_id[i])} {what} became "
               f"{np.array2string(value, precision=4)}{' (' + detail + ')' if detail else ''} — "
               "use more substeps, a stable integrator (SYMPLECTIC_EULER, RK4, IMPLICIT) or "
               "weaker forces/springs")
        return SimulationError(msg, obj=emitter, frame=inputs.frame, kind="emitter")

    def _age_kill(self, state: ParticleState, h: float, inputs) -> tuple[list, int]:
        """Age every particle by h; remove the dead. Returns per emitter (x, v) of the dead,
        and how many died. A dying particle's values are checked here (the sub-step's check
        comes after the deaths): one that went non-finite is a blow-up, not a death."""
        state.particle_age = state.particle_age + h
        dead = state.particle_age >= state.particle_life
        deaths = [_NO_DEATHS] * self.model.emitter_count
        if not dead.any():
            return deaths, 0
        x, v = state.particle_x[dead], state.particle_v[dead]
        if not (np.isfinite(x).all() and np.isfinite(v).all()):
            raise self._blame(state, inputs, "", state.particle_x, state.particle_v)
        for e in np.unique(state.particle_emitter[dead]):
            sel = dead & (state.particle_emitter == e)
            deaths[int(e)] = (state.particle_x[sel], state.particle_v[sel])
        state.keep(~dead)
        self._rest.keep(~dead)
        return deaths, len(x)

    def _emit(self, state, inputs, births, deaths, s0, s1, g, report) -> None:
        last = s1 >= 1.0
        deaths = list(deaths)  # born-dead particles are added to their emitter's deaths below
        for i in self.model.emit_order:
            e = self.model.emitters[i]
            if e.source == "DEATHS":
                b = sample_bursts(state.rngs[i], e, inputs.emitters[i], *deaths[e.parent])
                b.u = np.full(len(b), s1)
            else:
                b = births[i]
                if len(b) == 0:
                    continue
                b = b.take((b.u >= s0) & ((b.u < s1) | last))
            if len(b) == 0:
                continue
            tau = (s1 - b.u) * inputs.frame_dt  # time from birth to the end of this sub-step
            # Same rule as _age_kill (age >= life dies): these die inside this sub-step, at the
            # point of their ballistic flight where age == life; they never enter the State.
            gone = tau >= b.life
            if gone.any():
                life = b.life[gone][:, None]
                dx = b.x[gone] + b.v[gone] * life + 0.5 * g * life * life
                dv = b.v[gone] + g * life
                deaths[i] = (np.concatenate([deaths[i][0], dx]), np.concatenate([deaths[i][1], dv]))
                n_gone = int(gone.sum())
                report.born_dead += n_gone
                report.deaths += n_gone
                report.births += n_gone
                report.per_emitter_births[i] += n_gone
                b, tau = b.take(~gone), tau[~gone]
                if len(b) == 0:
                    continue
            if state.particle_count + len(b) > MAX_PARTICLES:
                raise SimulationError(
                    f"more than {MAX_PARTICLES:,} particles alive — lower the rate or lifetime",
                    obj=e.name, frame=inputs.frame, kind="emitter")
            x = b.x + b.v * tau[:, None] + 0.5 * g * (tau * tau)[:, None]
            v = b.v + g * tau[:, None]
            previous = state.last_born[i]
            ids = state.append(i, x, v, b.mass, tau, b.life, b.size)
            self._link(state, e, i, previous, ids, x)
            report.births += len(b)
            report.per_emitter_births[i] += len(b)

    @staticmethod
    def _link(state, settings, emitter, previous, ids, x) -> None:
        """Chain springs: each new particle is joined to the previous birth of its emitter."""
        if settings.link is None or len(ids) == 0:
            return
        prev = np.concatenate([[previous], ids[:-1]])
        ok = (prev >= 0) & np.isin(prev, state.particle_id)
        a, b = prev[ok], ids[ok]
        if settings.link.rest_length >= 0.0:
            rest = np.full(len(a), settings.link.rest_length)
        else:
            rest = np.linalg.norm(state.particle_x[state.index_of(a)] - x[ok], axis=1)
        state.add_links(a, b, rest, emitter)
