"""The contact layer every system shares: colliders over a frame interval (analytic shapes and
triangle meshes, moving and deforming), point contact queries and continuous response, and the
typed :class:`Contacts` result. Systems meet colliders here, never in each other's packages."""
from .contacts import ContactForce, Contacts
from .frame import COLLIDER_SHAPES, ColliderFrame, same_frames
from .kinds import KINDS, ColliderPaths
from .path import CONTACT_DISTANCE, SKIN, ColliderPath, Hits, SurfacePoints
from .response import PASSES, Response, reflect, respond, resting_contacts

__all__ = [
    "COLLIDER_SHAPES", "CONTACT_DISTANCE", "KINDS", "PASSES", "SKIN", "ColliderFrame",
    "ColliderPath", "ColliderPaths", "ContactForce", "Contacts", "Hits", "Response",
    "SurfacePoints", "reflect", "respond", "resting_contacts", "same_frames",
]
