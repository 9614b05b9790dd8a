"""A spring mesh's frame in the world: the record of one frame interval in progress (the
solver's sub-steps read and fill it) and the system the world steps (:mod:`.solver`)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..world import SolverSystem, WorldFrame
from . import attach
from . import sleep as sleep_
from .inputs import SpringDrive, SpringFrameInputs
from .model import SpringMeshState

if TYPE_CHECKING:
    from .solver import SpringMeshSolver


@dataclass
class FrameStep:
    """One frame interval of a spring mesh in progress (between begin and end of frame)."""

    state: SpringMeshState
    inputs: SpringFrameInputs
    paths: list  # the colliders' paths over the interval
    h: float  # sub-step [s]
    g: np.ndarray  # gravity (3,) [m/s^2]
    rest0: np.ndarray  # (n, 3) pin targets at the interval's start and end
    rest1: np.ndarray
    rest_speed: float  # [m/s] a bounce slower than this ends in contact
    hits: int = 0  # collisions handled
    held: attach.Held | None = None  # the attachments' paths this frame
    reactions: list = field(default_factory=list)  # impulses on bodies held by attachments
    conditions: sleep_.Conditions | None = None  # what its sub-steps depend on (:mod:`.sleep`)
    asleep: bool = False  # the mesh sleeps through the interval: its sub-steps do nothing
    start: np.ndarray | None = None  # (n, 3) positions at the interval's start (for sleeping)
    substeps: int = 1  # sub-steps of this interval (more than asked when coupled: the solver's)


class SpringMeshSystem(SolverSystem):
    """A spring-mesh state and its solver as one system of a
    :class:`~physanim.core.world.World`; its own per-frame input is a :class:`SpringDrive`.
    A frame reports the collisions handled."""

    def __init__(self, solver: SpringMeshSolver, state: SpringMeshState, name: str | None = None):
        super().__init__(solver, state, solver.model.settings.name if name is None else name)

    def inputs(self, frame: WorldFrame, drive: SpringDrive | None) -> SpringFrameInputs:
        return SpringFrameInputs.of(frame, drive)

    def begin_frame(self, frame: WorldFrame, paths, own) -> None:
        """Begin the interval; it takes the sub-steps the solver chose for it (a mesh coupled
        to bodies takes at least COUPLED_SUBSTEPS: :meth:`.solver.SpringMeshSolver.begin_frame`)."""
        super().begin_frame(frame, paths, own)
        self.substeps = self._step.substeps

    def report(self, step: FrameStep) -> int:
        return step.hits
