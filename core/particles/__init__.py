"""Particle systems: emitters, forces, analytic and mesh colliders and the sub-stepping solver."""
from .forces import Attractor, DampedSprings, Drag, Gravity, Vortex, Wind
from .model import ParticleModel, ParticleModelBuilder, ParticleState
from .output import emitter_arrays
from .settings import ColliderFrame, EmitterFrame, EmitterSettings, SpringLink
from .solver import FrameInputs, FrameReport, ParticleSolver

__all__ = [
    "Attractor", "ColliderFrame", "DampedSprings", "Drag", "EmitterFrame", "EmitterSettings",
    "FrameInputs", "FrameReport", "Gravity", "ParticleModel", "ParticleModelBuilder",
    "ParticleSolver", "ParticleState", "SpringLink", "Vortex", "Wind", "emitter_arrays",
]
