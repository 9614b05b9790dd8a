"""What drives a spring mesh over one frame interval: the world's frame and the mesh's own
input (:class:`SpringDrive`), as the solver reads them (:class:`SpringFrameInputs`)."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..contact import ColliderFrame
from ..forces import Wind
from ..world import WorldFrame


@dataclass
class SpringFrameInputs:
    """One frame interval [t0, t0 + frame_dt] of a spring mesh's world.

    Args:
        frame: scene frame at the start (messages). t0 [s], frame_dt [s]. gravity (3,).
        rest0, rest1: (n, 3) animated rest positions (world) at start/end — pin targets.
        targets: object name -> (m0, m1) world matrices of virtual-spring targets.
        colliders: analytic or mesh colliders. winds: wind force objects (pressure on faces).
        fields: other force objects (drag, attractor, vortex, ...): they act on the whole mesh
            as on one particle, shared by the vertices in proportion to their mass.
        bodies: rigid bodies stepped before the mesh this frame, by name (their inertia: an
            attachment to one moves it implicitly, :mod:`.attach`).
    """

    frame: int
    t0: float
    frame_dt: float
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    rest0: np.ndarray | None = None
    rest1: np.ndarray | None = None
    targets: dict = field(default_factory=dict)
    colliders: Sequence[ColliderFrame] = ()
    winds: Sequence[Wind] = ()
    fields: Sequence = ()
    bodies: dict = field(default_factory=dict)

    @classmethod
    def of(cls, frame: WorldFrame, drive: SpringDrive | None) -> SpringFrameInputs:
        """A spring mesh's inputs: the world's interval (its wind objects blow on the faces,
        the other forces act on the whole mesh) and what drives this mesh."""
        drive = drive or SpringDrive()
        return cls(frame.frame, frame.t0, frame.frame_dt, frame.gravity, drive.rest0,
                   drive.rest1, drive.targets, frame.colliders,
                   [f for f in frame.forces if isinstance(f, Wind)],
                   [f for f in frame.forces if not isinstance(f, Wind)], dict(frame.bodies))

    @property
    def world(self) -> WorldFrame:
        """What every system shares of this interval."""
        return WorldFrame(self.frame, self.t0, self.frame_dt, self.gravity, self.colliders,
                          [*self.winds, *self.fields], self.bodies)

    @property
    def drive(self) -> SpringDrive:
        return SpringDrive(self.rest0, self.rest1, self.targets)


@dataclass(frozen=True)
class SpringDrive:
    """What drives one spring mesh over a frame interval (its own input to the world).

    Attributes:
        rest0, rest1: (n, 3) animated rest positions (world) at start/end — pin targets; None:
            the model's rest shape.
        targets: object name -> (m0, m1) world matrices of virtual-spring targets.
    """

    rest0: np.ndarray | None = None
    rest1: np.ndarray | None = None
    targets: dict = field(default_factory=dict)
