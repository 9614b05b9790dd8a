"""Particle systems: emitters and the sub-stepping solver (colliders live in
:mod:`physanim.core.contact`, forces and springs in :mod:`physanim.core.forces`)."""
from .model import ParticleModel, ParticleModelBuilder, ParticleState
from .output import emitter_arrays
from .settings import POINT_CONSTRAINTS, EmitterFrame, EmitterSettings, PointConstraint, SpringLink
from .frame_inputs import FrameInputs, FrameReport, ParticleDrive
from .solver import ParticleSolver, ParticleSystem

__all__ = [
    "POINT_CONSTRAINTS", "PointConstraint", "EmitterFrame", "EmitterSettings", "FrameInputs", "FrameReport", "ParticleDrive",
    "ParticleModel", "ParticleModelBuilder", "ParticleSolver", "ParticleSystem", "ParticleState", "SpringLink",
    "emitter_arrays",
]
