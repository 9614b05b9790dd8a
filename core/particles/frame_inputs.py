"""What the particle system takes for one frame interval (:class:`FrameInputs`, its own part
:class:`ParticleDrive`) and reports of it (:class:`FrameReport`)."""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from ..contact import ColliderFrame
from ..forces import Force
from ..world import BodyInertia, WorldFrame
from .pair_collisions import ParticleCollisions
from .settings import EmitterFrame


@dataclass
class FrameInputs:
    """What the scene says about one frame interval [t0, t0 + frame_dt].

    Args:
        frame: scene frame at the interval's start (named in messages).
        t0: start time [s]. frame_dt: interval length [s].
        gravity: (3,) [m/s^2].
        emitters: one :class:`EmitterFrame` per model emitter, same order.
        colliders: colliders (analytic shapes or triangle meshes) with their motion over the
            interval.
        forces: force objects (drag, wind, attractors, ...) for this interval.
        interactions: forces among the particles (:mod:`..forces.interactions`: mutual
            gravity, Lennard-Jones, Coulomb), bound to the particles each sub-step.
        collisions: collisions among the particles (:mod:`.pair_collisions`).
        bodies: the rigid bodies of the world stepped first, by name (:class:`~..world.
            BodyInertia`): particles tied to one pull it (:mod:`.ties`).
    """

    frame: int
    t0: float
    frame_dt: float
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    emitters: Sequence[EmitterFrame] = ()
    colliders: Sequence[ColliderFrame] = ()
    forces: Sequence[Force] = ()
    interactions: Sequence = ()
    collisions: Sequence[ParticleCollisions] = ()
    bodies: Mapping[str, BodyInertia] = field(default_factory=dict)

    @classmethod
    def of(cls, frame: WorldFrame, drive: ParticleDrive) -> FrameInputs:
        """The particles' inputs: the world's interval, the emitters' values and the
        interactions."""
        return cls(frame.frame, frame.t0, frame.frame_dt, frame.gravity, drive.emitters,
                   frame.colliders, frame.forces, drive.interactions, drive.collisions,
                   frame.bodies)

    @property
    def drive(self) -> ParticleDrive:
        """What only the particles read of this interval."""
        return ParticleDrive(self.emitters, self.interactions, self.collisions)

    @property
    def world(self) -> WorldFrame:
        """What every system shares of this interval."""
        return WorldFrame(self.frame, self.t0, self.frame_dt, self.gravity, self.colliders,
                          self.forces, self.bodies)


@dataclass(frozen=True)
class ParticleDrive:
    """The particle system's own input for one interval (besides the world's): one
    :class:`EmitterFrame` per model emitter, same order, and the interactions among the
    particles."""

    emitters: Sequence[EmitterFrame] = ()
    interactions: Sequence = ()
    collisions: Sequence[ParticleCollisions] = ()


@dataclass
class FrameReport:
    """What happened during one frame.

    Attributes:
        births: all births (what the rates asked for). per_emitter_births: the same per emitter.
        deaths: particles that reached their life span, ``born_dead`` included.
        born_dead: births whose whole life span fit inside their birth sub-step: they never
            enter the State (no id, never cached), but their sub-emitters burst where they die.
        Particles alive at the end = alive at the start + births - deaths. at_rest: of them,
        those the last sub-step left exactly as they were, which the next skips (:mod:`.rest`).
    """

    births: int = 0
    deaths: int = 0
    born_dead: int = 0
    collisions: int = 0
    integrator_steps: int = 0
    alive: int = 0
    at_rest: int = 0
    per_emitter_births: list[int] = field(default_factory=list)
