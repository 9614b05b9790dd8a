"""Reading meshes in bulk: the one place the add-on turns a Blender mesh into numpy arrays."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class MeshArrays:
    """A mesh's local vertex positions and, when asked for, its topology.

    Attributes:
        co: (n, 3) float64 local positions [m].
        triangles: (m, 3) int64 loop triangles, or None.
        edges: (e, 2) int32 vertex pairs, or None.
        loop_start, loop_total, loop_vertices: int32 polygon arrays, or None.
        weights: vertex-group name -> (n,) weights (0 where a vertex is not in the group).
    """

    co: np.ndarray
    triangles: np.ndarray | None = None
    edges: np.ndarray | None = None
    loop_start: np.ndarray | None = None
    loop_total: np.ndarray | None = None
    loop_vertices: np.ndarray | None = None
    weights: dict = field(default_factory=dict)


def vertex_positions(me) -> np.ndarray:
    """(n, 3) float64 local vertex positions of a mesh (read as float32, Blender's storage)."""
    co = np.empty(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64)


def mesh_polygons(me) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A mesh's vertex positions (n, 3) float64 and its polygons as loop_start, loop_total and
    loop_vertices int32 arrays."""
    start = np.empty(len(me.polygons), np.int32)
    total = np.empty(len(me.polygons), np.int32)
    me.polygons.foreach_get("loop_start", start)
    me.polygons.foreach_get("loop_total", total)
    loops = np.empty(len(me.loops), np.int32)
    me.loops.foreach_get("vertex_index", loops)
    return vertex_positions(me), start, total, loops


def loop_triangles(me) -> np.ndarray:
    """(m, 3) int64 vertex indices of the mesh's loop triangles."""
    me.calc_loop_triangles()
    tris = np.empty(len(me.loop_triangles) * 3, np.int32)
    me.loop_triangles.foreach_get("vertices", tris)
    return tris.reshape(-1, 3).astype(np.int64)


def _weights(ob, me) -> dict:
    names = {g.index: g.name for g in ob.vertex_groups}
    weights = {name: np.zeros(len(me.vertices)) for name in names.values()}
    for v in me.vertices:  # set-up only (once per bake): Blender has no bulk access to these
        for g in v.groups:
            if g.group in names:
                weights[names[g.group]][v.index] = g.weight
    return weights


def evaluated_mesh(ob, depsgraph, triangles: bool = False, topology: bool = False) -> MeshArrays:
    """``ob``'s evaluated mesh (modifiers, shape keys) at the depsgraph's frame.

    Args:
        triangles: also read the loop triangles.
        topology: also read edges, polygons, triangles and vertex-group weights.
    """
    ob_eval = ob.evaluated_get(depsgraph)
    me = ob_eval.to_mesh()
    try:
        if not topology:
            return MeshArrays(vertex_positions(me), loop_triangles(me) if triangles else None)
        co, start, total, loops = mesh_polygons(me)
        edges = np.empty(len(me.edges) * 2, np.int32)
        me.edges.foreach_get("vertices", edges)
        return MeshArrays(co, loop_triangles(me), edges.reshape(-1, 2), start, total, loops,
                          _weights(ob, me))
    finally:
        ob_eval.to_mesh_clear()
