"""The world stepper: every system of a run advanced together, frame by frame, in sub-steps.

One frame interval, as a table of contents (:meth:`World.advance`):

    leading systems      systems that lead (rigid bodies) step their whole frame first; the
                         others then meet their bodies as moving colliders
    kinematic colliders  the colliders' motion over the interval, made once per stage
                         (each sub-step samples it at its own times)
    begin frame          each system takes the interval's inputs: the shared :class:`WorldFrame`
                         and its own (emitter values, animated pin targets, ...)
    sub-steps            every system's sub-steps in time order; one sub-step of a system runs
                         its passes: forces -> integrate -> contacts -> response -> checks
    end frame            each system's report of the interval
    reactions            what the followers' constraints did to the leaders' bodies (a cloth
                         attached to a rigid body) goes back to those bodies as impulses

Systems plug in through :class:`WorldSystem`: adding a kind of system (rigid bodies) adds a
class, not a branch in this loop. A system that fails (bad input, a blow-up) is dropped and
reported; the others go on, and only when no system is left does the failure stop the run.
Systems may take different numbers of sub-steps per frame: their sub-steps interleave by end
time (with the same count, all systems finish sub-step k before any starts k + 1).

Two-way coupling between a leader and a follower is an exchange of impulses: the follower holds
its points on the leader's bodies along the paths they took this frame, and hands back the
impulses that took (:class:`Reaction`); the leader adds them to its bodies' momenta at the
frame's end, so the coupled momentum is conserved exactly and the bodies feel the pull from the
next frame on (a lag of one frame in position, none in momentum).
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np

from .bounds import DEFAULT_BOUNDS, StateBounds
from .contact import ColliderFrame, ColliderPath, ColliderPaths
from .errors import PhysanimError
from .integrators import SPRING_INTEGRATORS

MAX_SUBSTEPS = 10_000  # per frame: keeps a bake finite


@dataclass(frozen=True)
class SolverSettings:
    """How a system steps: the scene's solver options (a system may override its own).

    Attributes:
        integrator: one of :data:`physanim.core.integrators.INTEGRATORS` (spring meshes also
            ``"BDF2"``: :data:`~physanim.core.integrators.SPRING_INTEGRATORS`).
        substeps: sub-steps per frame (1..MAX_SUBSTEPS).
        tolerance: relative tolerance of the adaptive integrator (RK45) and implicit solves.
        bounds: a simulated point beyond them (position or speed) stops the run with an error.
    """

    integrator: str = "SYMPLECTIC_EULER"
    substeps: int = 1
    tolerance: float = 1e-4
    bounds: StateBounds = DEFAULT_BOUNDS

    def __post_init__(self):
        if self.integrator not in SPRING_INTEGRATORS:
            raise ValueError(f"unknown integrator {self.integrator!r}; choose one of "
                             f"{', '.join(SPRING_INTEGRATORS)}")
        if isinstance(self.substeps, bool) or int(self.substeps) != self.substeps \
                or self.substeps < 1:
            raise ValueError(f"substeps must be an integer >= 1 (got {self.substeps})")
        if self.substeps > MAX_SUBSTEPS:
            raise ValueError(f"substeps must be at most {MAX_SUBSTEPS} (got {self.substeps})")
        object.__setattr__(self, "substeps", int(self.substeps))
        if not (math.isfinite(self.tolerance) and self.tolerance > 0.0):
            raise ValueError(f"tolerance must be finite and > 0 (got {self.tolerance!r})")


@dataclass(frozen=True)
class WorldFrame:
    """What the scene says about one frame interval [t0, t0 + frame_dt], for every system.

    Attributes:
        frame: scene frame at the interval's start (named in messages).
        t0: start time [s]. frame_dt: interval length [s].
        gravity: (3,) [m/s^2], from the caller (the scene's).
        colliders: colliders with their motion over the interval.
        forces: force objects (drag, wind, attractors, ...) for the interval.
        bodies: the leaders' dynamic bodies at the interval's end, by name (what a follower
            coupled to them needs to move them implicitly).
        samples: fractions of the interval, strictly between 0 and 1 and ascending, at which
            each system's pose is wanted as well (frames shown in slow motion, see
            :mod:`.controls.timing`): :attr:`WorldReport.poses`.
    """

    frame: int
    t0: float
    frame_dt: float
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    colliders: Sequence[ColliderFrame] = ()
    forces: Sequence[Any] = ()
    bodies: Mapping[str, BodyInertia] = field(default_factory=dict)
    samples: tuple[float, ...] = ()


@dataclass(frozen=True)
class BodyInertia:
    """A leader's body as a follower coupled to it sees it at the frame's end.

    Attributes: mass [kg]; inertia: (3, 3) world inertia tensor about the centre of mass
    [kg m^2]; centre: (3,) centre of mass [m]; velocity: (6,) linear [m/s] and angular
    [rad/s] velocity; velocity0: (3,) linear velocity at the frame's start [m/s].
    """

    mass: float
    inertia: np.ndarray
    centre: np.ndarray
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(6))
    velocity0: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass(frozen=True)
class Reaction:
    """Impulses a follower's constraints give to a leader's body over one frame interval.

    Attributes:
        body: the body's name. point: (k, 3) where they act, world, at the interval's end [m].
        impulse: (k, 3) the impulses on the body [N s] (the follower took the opposite).
        move: (6,) how far the body moved meanwhile in the follower's implicit steps: its
            centre [m] and a rotation vector about it [rad] (backward Euler moves a body by
            h times the velocity change it solves for; the leader puts it there).
    """

    body: str
    point: np.ndarray
    impulse: np.ndarray
    move: np.ndarray = field(default_factory=lambda: np.zeros(6))


def merged(reactions: Sequence[Reaction]) -> list[Reaction]:
    """Reactions on the same bodies (a frame's sub-steps), one per body: impulses at their
    points concatenated, moves added."""
    out: dict[str, list] = {}
    for r in reactions:
        out.setdefault(r.body, []).append(r)
    return [Reaction(body, np.concatenate([r.point for r in rs]),
                     np.concatenate([r.impulse for r in rs]), sum(r.move for r in rs))
            for body, rs in out.items()]


class WorldSystem(Protocol):
    """A system the world steps (particles, a spring mesh, ...).

    Attributes:
        name: what messages call it. substeps: its sub-steps per frame.
    """

    name: str
    substeps: int
    leads: bool  # steps its whole frame before the others, who meet it as moving colliders

    def frame_colliders(self) -> list[ColliderFrame]:
        """A leading system's bodies as colliders over the frame it just finished ([] if it
        does not lead)."""

    def frame_bodies(self) -> dict[str, BodyInertia]:
        """A leading system's dynamic bodies at the end of the frame it just finished."""

    def begin_frame(self, frame: WorldFrame, paths: Sequence[ColliderPath], own: Any) -> None:
        """Take the interval's inputs: ``paths`` are the colliders' motion over it, ``own`` what
        only this system reads (None when the caller gave nothing)."""

    def substep(self, k: int) -> None:
        """Advance sub-step ``k`` (0..substeps-1) of the interval begun last."""

    def end_frame(self) -> Any:
        """Finish the interval; returns the system's report of it."""

    def reactions(self) -> list[Reaction]:
        """A follower's impulses on leaders' bodies during the interval just ended."""

    def absorb(self, reactions: Sequence[Reaction]) -> None:
        """A leader takes the followers' impulses on its bodies (those it does not simulate it
        ignores)."""

    def pose(self) -> Any:
        """A copy of what is drawn of the system now (its points' positions, ...)."""

    def blend(self, a: Any, b: Any, w: float) -> Any:
        """The pose at the fraction ``w`` in (0, 1] of a sub-step from pose ``a`` to pose
        ``b`` (``b`` itself at 1)."""


class SolverSystem:
    """A :class:`WorldSystem` made of a solver and the state it advances. The solver offers
    ``substeps``, ``begin_frame(state, inputs, paths) -> step`` and ``substep(step, k)``;
    subclasses say what the solver's inputs are (:meth:`inputs`) and what the frame reports
    (:meth:`report`)."""

    leads = False

    def __init__(self, solver, state, name: str):
        self.solver, self.state, self.name = solver, state, name
        self.substeps = solver.substeps
        self._step = None  # the frame interval in progress

    def frame_colliders(self) -> list[ColliderFrame]:
        return []

    def frame_bodies(self) -> dict[str, BodyInertia]:
        return {}

    def inputs(self, frame: WorldFrame, own: Any):
        raise NotImplementedError

    def report(self, step) -> Any:
        raise NotImplementedError

    def begin_frame(self, frame: WorldFrame, paths: Sequence[ColliderPath], own: Any) -> None:
        self._step = self.solver.begin_frame(self.state, self.inputs(frame, own), paths)

    def substep(self, k: int) -> None:
        self.solver.substep(self._step, k)

    def end_frame(self) -> Any:
        step, self._step = self._step, None
        self._last = step
        return self.report(step)

    def reactions(self) -> list[Reaction]:
        last = getattr(self, "_last", None)
        return list(getattr(last, "reactions", ())) if last is not None else []

    def absorb(self, reactions: Sequence[Reaction]) -> None:
        absorb = getattr(self.solver, "absorb", None)
        if absorb is not None:
            absorb(self.state, reactions)

    def pose(self) -> Any:
        return self.state.pose()

    def blend(self, a: Any, b: Any, w: float) -> Any:
        return type(b).between(a, b, w)


@dataclass
class WorldReport:
    """One frame interval: each system's report, and the systems that failed in it."""

    reports: dict = field(default_factory=dict)  # system -> its end_frame() report
    failed: list = field(default_factory=list)  # (system, exception), in the order they failed
    poses: dict = field(default_factory=dict)  # system -> its pose at each of frame.samples


class World:
    """Advances its systems frame by frame (see the module docstring).

    Args:
        systems: the systems, in the order they run within a sub-step time.
        colliders: makes each interval's collider paths and keeps what lasts between intervals
            (mesh hierarchies); owned by the caller, who releases it when the run ends.
    """

    def __init__(self, systems: Sequence[WorldSystem], colliders: ColliderPaths | None = None):
        self.systems: list[WorldSystem] = list(systems)
        self.colliders = ColliderPaths() if colliders is None else colliders

    def advance(self, frame: WorldFrame, own: Mapping[WorldSystem, Any] | None = None
                ) -> WorldReport:
        """Advance every live system by the interval ``frame``; ``own[system]`` is that system's
        own input. Failed systems are dropped and listed in the report.

        Raises:
            PhysanimError, ValueError: the failure that left no system running.
        """
        report = WorldReport()
        leaders = [s for s in self.systems if s.leads]
        others = [s for s in self.systems if not s.leads]
        if leaders:
            self._stage(report, leaders, frame, own or {})
        if others:  # they meet the leaders' bodies where those went this frame
            led = [s for s in leaders if s in self.systems]
            moving = [c for s in led for c in s.frame_colliders()]
            bodies = {name: b for s in led for name, b in s.frame_bodies().items()}
            staged = replace(frame, colliders=(*frame.colliders, *moving),
                             bodies={**frame.bodies, **bodies}) if moving else frame
            self._stage(report, others, staged, own or {})
            self._react(report, leaders, others)
        return report

    def _react(self, report: WorldReport, leaders: list, others: list) -> None:
        """The followers' impulses on the leaders' bodies, to the leaders."""
        reactions = [r for s in others if s in self.systems for r in s.reactions()]
        if reactions:
            for system in leaders:
                if system in self.systems:
                    self._guarded(report, system, system.absorb, reactions)

    def _stage(self, report: WorldReport, systems: list, frame: WorldFrame, own) -> None:
        """One stage of the frame for ``systems``: begin, sub-steps in time order, end."""
        paths = self.kinematic_colliders(frame)
        for system in systems:
            self._guarded(report, system, system.begin_frame, frame, paths, own.get(system))
        for system, k in self.substep_order(systems):
            if system in self.systems:
                self._substep(report, system, k, frame.samples)
        for system in systems:
            if system in self.systems:
                done = self._guarded(report, system, system.end_frame)
                if system in self.systems:
                    report.reports[system] = done

    def _substep(self, report: WorldReport, system: WorldSystem, k: int,
                 samples: Sequence[float]) -> None:
        """Sub-step ``k`` of ``system``, and its poses at the samples that fall in it."""
        n = system.substeps
        inside = [s * n - k for s in samples if k < s * n <= k + 1]
        before = system.pose() if inside else None
        self._guarded(report, system, system.substep, k)
        if inside and system in self.systems:
            after = system.pose()
            report.poses.setdefault(system, []).extend(system.blend(before, after, w)
                                                       for w in inside)

    # -- passes ---------------------------------------------------------------------------------
    def kinematic_colliders(self, frame: WorldFrame) -> list[ColliderPath]:
        """The colliders' motion over the interval, shared by every system."""
        return self.colliders.of(frame.colliders, frame.frame_dt)

    def substep_order(self, systems: Sequence[WorldSystem] | None = None
                      ) -> list[tuple[WorldSystem, int]]:
        """Every system's sub-steps, by end time (k + 1) / substeps, then system order."""
        systems = list(self.systems if systems is None else systems)
        steps = [((k + 1) / s.substeps, i, k) for i, s in enumerate(systems)
                 for k in range(s.substeps)]
        return [(systems[i], k) for _, i, k in sorted(steps)]

    def drop(self, system: WorldSystem) -> None:
        """Take a system out of the run (its owner found it failed)."""
        if system in self.systems:
            self.systems.remove(system)

    def _guarded(self, report: WorldReport, system: WorldSystem, call, *args):
        """``call(*args)`` of one system: its failure drops that system, and stops the run
        only when it was the last one."""
        try:
            return call(*args)
        except (PhysanimError, ValueError) as exc:
            report.failed.append((system, exc))
            self.drop(system)
            if not self.systems:
                raise
            return None
