"""What the rigid-body system is given for one frame interval (:class:`RigidFrameInputs`, its own
part :class:`RigidPaths`) and what it reports of it (:class:`RigidReport`)."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from ..contact import ColliderFrame
from ..world import WorldFrame


@dataclass
class RigidFrameInputs:
    """One frame interval of the rigid bodies' world.

    Args:
        frame: scene frame at the start (messages). t0 [s], frame_dt [s]. gravity (3,).
        colliders: the frame's colliders. kinematic: body index -> (k + 1, 4, 4) world matrices
            of the object of a body that follows its animation over this interval (k >= 1);
            the others are simulated. A body leaves its path with the path's velocity (an
            arm lets a box go), and joins a path where it starts.
        joint_paths: joint index -> (k + 1, 4, 4) world frames of a joint's FRAME side over
            this interval (an animated object holding it); others stay where they were placed.
        joint_settings: the joints' settings for this interval (one per joint: their keyed
            limits, motors, springs and breaking, :meth:`JointModel.with_values`); None: the
            model's.
    """

    frame: int
    t0: float
    frame_dt: float
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    colliders: Sequence[ColliderFrame] = ()
    kinematic: dict = field(default_factory=dict)
    joint_paths: dict = field(default_factory=dict)
    joint_settings: list | None = None

    @classmethod
    def of(cls, frame: WorldFrame, paths: RigidPaths | None) -> RigidFrameInputs:
        paths = paths or RigidPaths()
        return cls(frame.frame, frame.t0, frame.frame_dt, frame.gravity, frame.colliders,
                   paths.kinematic, paths.joints, paths.joint_settings)

    @property
    def paths(self) -> RigidPaths:
        return RigidPaths(self.kinematic, self.joint_paths, self.joint_settings)

    @property
    def world(self) -> WorldFrame:
        return WorldFrame(self.frame, self.t0, self.frame_dt, self.gravity, self.colliders)


@dataclass
class RigidPaths:
    """The rigid bodies' own input for a frame interval: the paths of the bodies that follow
    their animation (``kinematic``), of the joints' animated frames (``joints``) and the
    joints' keyed settings (``joint_settings``), as in :class:`RigidFrameInputs`."""

    kinematic: dict = field(default_factory=dict)
    joints: dict = field(default_factory=dict)
    joint_settings: list | None = None


@dataclass
class RigidReport:
    """A frame: contact points found, the deepest overlap [m] at its end, bodies moving,
    bodies asleep."""

    contacts: int = 0
    overlap: float = 0.0
    moving: int = 0
    sleeping: int = 0
    broken: list = field(default_factory=list)  # names of the joints that broke this frame
