"""PhysAnim core: physically based animation in numpy. Never imports Blender modules.

Units are SI (metres, seconds, kilograms) and the world is right-handed with an arbitrary gravity
vector; frames, Blender's axes and property names live only in ``addon/``.
"""
from .errors import PhysanimError, SimulationError

__all__ = ["PhysanimError", "SimulationError"]
