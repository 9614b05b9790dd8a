"""Forces shared by every point system: field forces (:mod:`.fields`), damped springs
(:mod:`.springs`) and the constraint forces of hard constraints (:mod:`.constraints`, their
kinds in :mod:`.constraint_rows`)."""
from .constraint_rows import OnCurves, OnPlanes, Pins, Rods, Rows, Tethers, on_circles, on_spheres
from .constraints import Feedback, HardConstraints, Projection
from .fields import Attractor, Drag, Force, Gravity, ParticleView, Vortex, Wind
from .springs import AnchorSprings, DampedSprings

__all__ = ["AnchorSprings", "Attractor", "DampedSprings", "Drag", "Feedback", "Force", "Gravity",
           "HardConstraints", "OnPlanes", "ParticleView", "Pins", "Projection", "Rods", "Rows",
           "OnCurves", "Tethers", "Vortex", "Wind", "on_circles", "on_spheres"]
