"""Animator controls (after Lasseter's principles of animation): simulations an animator can
direct — follow-through (:mod:`.follow`), squash and stretch (:mod:`.squash`)."""
from .follow import FollowSettings, follow_through, transition
from .squash import ImpactTracker, SquashSettings, euler_xyz, log_deformation, principal

__all__ = ["FollowSettings", "ImpactTracker", "SquashSettings", "euler_xyz", "follow_through",
           "log_deformation", "principal", "transition"]
