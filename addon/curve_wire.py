"""A Curve object as a wire for an emitter's particles (On Wire on a curve): its evaluated
spline's centre line, in order, in world space, read at each frame."""
from __future__ import annotations

import contextlib

import numpy as np

from ..core.errors import PhysanimError
from .mesh_read import evaluated_mesh


def curve_wire(ob, matrix: np.ndarray, depsgraph, frame) -> tuple[np.ndarray, bool]:
    """A Curve object's wire at the depsgraph's frame: its evaluated spline (at the curve's
    resolution, modifiers applied) as (P, 3) world points in order, and whether it is closed
    (Cyclic); neighbours at one place (a Bezier point's zero-length segment) are merged. An
    error naming the object when it is not one spline."""
    with _centreline(ob.data, depsgraph):
        mesh = evaluated_mesh(ob, depsgraph, topology=True)
    line = polyline(mesh.edges, len(mesh.co)) if mesh.edges is not None else None
    if line is None:
        raise PhysanimError("On Wire runs particles along one spline: this curve has "
                            f"{len(ob.data.splines)} splines (or one that branches) — keep one "
                            "spline, or separate the others into their own objects",
                            obj=ob.name, frame=frame, kind="constraint")
    order, closed = line
    pts = mesh.co[order] @ matrix[:3, :3].T + matrix[:3, 3]
    keep = np.ones(len(pts), bool)
    keep[1:] = np.any(pts[1:] != pts[:-1], axis=1)
    if closed and len(pts) > 1 and not np.any(pts[-1] != pts[0]):
        keep[-1] = False
    return pts[keep], closed


def polyline(edges: np.ndarray, count: int) -> tuple[np.ndarray, bool] | None:
    """The vertex order of ``count`` vertices joined by ``edges`` (e, 2) into one line — an open
    chain (two ends) or a closed loop — and whether it is closed; None when the edges make
    anything else (several pieces, a branch, a loose vertex)."""
    if count < 2 or len(edges) not in (count - 1, count):
        return None
    degree = np.bincount(edges.ravel(), minlength=count)
    ends = np.nonzero(degree == 1)[0]
    closed = len(edges) == count
    if np.any(degree > 2) or np.any(degree == 0) or len(ends) != (0 if closed else 2):
        return None
    neighbours = [[] for _ in range(count)]
    for a, b in edges.tolist():
        neighbours[a].append(b)
        neighbours[b].append(a)
    order = [int(ends[0]) if len(ends) else 0]
    previous = -1
    for _ in range(count - 1):
        here = order[-1]
        step = next((n for n in neighbours[here] if n != previous), None)
        if step is None or (len(order) > 1 and step == order[0]):
            return None
        previous = here
        order.append(step)
    return (np.array(order), closed) if len(set(order)) == count else None


@contextlib.contextmanager
def _centreline(curve, depsgraph):
    """Within: ``curve`` evaluates to its centre line only — no bevel, extrusion or fill (what
    a wire shows is not what it is); its settings come back after, whatever happens."""
    keep = {key: getattr(curve, key) for key in ("extrude", "bevel_depth", "bevel_mode",
                                                  "fill_mode")}
    bare = {"extrude": 0.0, "bevel_depth": 0.0, "bevel_mode": 'ROUND'}
    if curve.dimensions == '2D':
        bare["fill_mode"] = 'NONE'
    changed = {key: value for key, value in bare.items() if keep[key] != value}
    try:
        for key, value in changed.items():
            setattr(curve, key, value)
        if changed:
            depsgraph.update()
        yield
    finally:
        for key in changed:
            setattr(curve, key, keep[key])
        if changed:
            depsgraph.update()


def wire_ends(start, end) -> tuple:
    """PointConstraint's (points0, points1, cyclic) from two :func:`curve_wire` results (or
    None, None, False for no wire)."""
    if start is None or end is None:
        return None, None, False
    return start[0], end[0], start[1]
