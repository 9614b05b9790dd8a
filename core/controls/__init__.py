"""Animator controls (after Lasseter's principles of animation): simulations an animator can
direct — follow-through (:mod:`.follow`)."""
from .follow import FollowSettings, follow_through, transition

__all__ = ["FollowSettings", "follow_through", "transition"]
