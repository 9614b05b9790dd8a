"""Particle systems: emitters, particle springs and the sub-stepping solver (colliders live in
:mod:`physanim.core.contact`, field forces in :mod:`physanim.core.forces`)."""
from .forces import DampedSprings
from .model import ParticleModel, ParticleModelBuilder, ParticleState
from .output import emitter_arrays
from .settings import EmitterFrame, EmitterSettings, SpringLink
from .solver import FrameInputs, FrameReport, ParticleSolver

__all__ = [
    "DampedSprings", "EmitterFrame", "EmitterSettings", "FrameInputs", "FrameReport",
    "ParticleModel", "ParticleModelBuilder", "ParticleSolver", "ParticleState", "SpringLink",
    "emitter_arrays",
]
