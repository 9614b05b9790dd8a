"""Forces shared by every system: field forces (:mod:`.fields`) and damped springs
(:mod:`.springs`)."""
from .fields import Attractor, Drag, Force, Gravity, ParticleView, Vortex, Wind
from .springs import AnchorSprings, DampedSprings

__all__ = ["AnchorSprings", "Attractor", "DampedSprings", "Drag", "Force", "Gravity",
           "ParticleView", "Vortex", "Wind"]
