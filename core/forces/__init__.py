"""Forces shared by every system (see :mod:`.fields`)."""
from .fields import Attractor, Drag, Force, Gravity, ParticleView, Vortex, Wind

__all__ = ["Attractor", "Drag", "Force", "Gravity", "ParticleView", "Vortex", "Wind"]
