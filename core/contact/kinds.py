"""Which path class handles each collider shape, and the object that turns a frame interval's
colliders into paths for every system of a run."""
from __future__ import annotations

from collections.abc import Sequence

from .analytic import SHAPES as ANALYTIC_SHAPES
from .analytic import AnalyticPath
from .frame import ColliderFrame
from .mesh import MeshHierarchies, MeshPath
from .path import ColliderPath

KINDS: dict[str, type[ColliderPath]] = {
    **{shape: AnalyticPath for shape in ANALYTIC_SHAPES},
    "MESH": MeshPath,
}


class ColliderPaths:
    """Makes the collider paths of each frame interval and keeps what lasts between intervals
    (mesh hierarchies). One per run — a bake, a test — owned by the caller and dropped with it.
    """

    def __init__(self):
        self.hierarchies = MeshHierarchies()
        # by collider name: the last interval's frame, frame_dt and path of each kind whose
        # paths hold nothing but their frame (a still ground gets one path for the whole run)
        self._kept: dict[str, tuple[ColliderFrame, float, ColliderPath]] = {}

    def __getstate__(self) -> dict:
        """Saved (a checkpoint) without the kept mesh paths, which the next interval makes
        again from the hierarchies saved with it (the same answers)."""
        state = dict(self.__dict__)
        state["_kept"] = {name: kept for name, kept in self._kept.items()
                          if not isinstance(kept[2], MeshPath)}
        return state

    def release(self) -> None:
        """Drop what is kept between frame intervals (a run calls this when it ends)."""
        self.hierarchies.clear()
        self._kept.clear()

    def of(self, frames: Sequence[ColliderFrame], frame_dt: float) -> list[ColliderPath]:
        self.hierarchies.in_use(sum(frame.shape == "MESH" for frame in frames))
        return [self.path(frame, frame_dt) for frame in frames]

    def path(self, frame: ColliderFrame, frame_dt: float) -> ColliderPath:
        kind = KINDS.get(frame.shape)
        if kind is None:
            raise ValueError(f'collider "{frame.name}": no collider kind handles shape '
                             f"{frame.shape!r}")
        kept = self._kept.get(frame.name)
        if kept is not None and kept[1] == frame_dt and kept[0].same_as(frame):
            return kept[2]
        path = kind.build(frame, frame_dt, self)
        if path.reusable:
            self._kept[frame.name] = (frame, frame_dt, path)
        else:
            self._kept.pop(frame.name, None)
        return path
