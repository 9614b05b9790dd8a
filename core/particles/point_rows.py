"""A point constraint's rows for one sub-step (:class:`.settings.PointConstraint` on the
particles it holds, as :mod:`..forces` constraint rows): its object moves linearly over the
frame."""
from __future__ import annotations

import numpy as np

from ..forces import OnCurves, OnPlanes, Tethers, on_circles
from .settings import PointConstraint


def point_rows(c: PointConstraint, held: np.ndarray, s0: float, t: float, h: float,
               frame_dt: float) -> list:
    """The rows of point constraint ``c`` on particles ``held`` for the sub-step starting at
    ``s0`` of the frame (time ``t``): its frame's origin moves linearly over the frame, its axis
    is taken at the sub-step's start."""
    if c.kind == "ON_CURVE":  # its points move linearly over the frame
        return [OnCurves(held, c.points0 + s0 * (c.points1 - c.points0),
                         (c.points1 - c.points0) / frame_dt, c.cyclic, t)]
    o0, o1 = c.matrix0[:3, 3], c.matrix1[:3, 3]
    origin, velocity = o0 + s0 * (o1 - o0), (o1 - o0) / frame_dt
    axis = c.matrix0[:3, 2] + s0 * (c.matrix1[:3, 2] - c.matrix0[:3, 2])
    axis = axis / np.linalg.norm(axis)
    if c.kind == "ON_PLANE":
        return [OnPlanes(held, origin, axis, velocity, t)]
    if c.kind == "ON_SPHERE":
        return [Tethers(held, origin, c.radius, velocity, t)]
    return on_circles(held, origin, axis, c.radius, velocity, t)
