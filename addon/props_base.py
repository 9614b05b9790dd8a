"""What every property module shares: the STATIC option set and the properties several roles
have alike."""
from __future__ import annotations

from bpy.props import FloatProperty

# Read once per bake (topology, seeds, shapes of curves, solver settings): not keyframable, so
# no one keys them expecting an effect. Everything else is sampled per frame by the extract step.
STATIC: set[str] = set()


def squash_property(description: str):
    """Squash & Stretch amount (0: off), as emitters and rigid bodies have it."""
    return FloatProperty(name="Squash & Stretch", min=0.0, max=20.0, soft_max=3.0, default=0.0,
                         options=STATIC, description=description)


def recovery_property():
    """The recovery time of a Squash & Stretch impact."""
    return FloatProperty(name="Recovery", min=0.001, max=10.0, default=0.15,
                         unit='TIME_ABSOLUTE', options=STATIC,
                         description="Seconds for an impact's squash to fall to 1/e")
