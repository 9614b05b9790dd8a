"""Box features, their persistent ids, and the face clipping of the box-box manifold.

Numbering (a box's local axes x, y, z = 0, 1, 2; a sign per axis says which side):

* vertex v in [0, 8): bit k of v set when the vertex lies on the + side of axis k;
* edge e in [0, 12): 4 k + (bits of its two fixed signs, lower axis first) for an edge along k;
* face f in [0, 6): 2 k + (1 on the + side of axis k).

A face-face contact point is one of: a vertex of one box on a face of the other, or an edge of
one crossing an edge of the other (in the clip, an incident edge cut by a side plane of the
reference face: that plane meets the reference face in an edge). Its id names those features
in the order (A's, B's), so it does not depend on which box held the reference face: a box
resting on another keeps its ids when rounding flips the reference from one box to the other.
"""
from __future__ import annotations

import numpy as np

from ..transforms import cross

CAPACITY = 8  # a rectangle clipped by four planes has at most 8 corners
# a corner within this fraction of the half extent of a side plane counts as on it (inside)
ON_PLANE = 1e-6

# feature id ranges: (vertex of A, face of B), (face of A, vertex of B), (edge of A, edge of B)
VERTEX_FACE, FACE_VERTEX, EDGE_EDGE = 0, 48, 96

# clip labels of polygon corners: incident corner c (0..3); incident edge e cut by side plane k
# (EDGE_CUT + 4 e + k); two side planes k1, k2 meeting (PLANE_CORNER + 4 k1 + k2).
# Polygon edges: incident edge e (0..3) or lying along side plane k (4 + k).
EDGE_CUT, PLANE_CORNER = 4, 20


def edge_id(axis, signs):
    """Ids of edges along ``axis`` (...,) whose other two coordinates have ``signs`` (..., 3)."""
    axis = np.asarray(axis)
    lower = np.minimum((axis + 1) % 3, (axis + 2) % 3)
    higher = 3 - axis - lower
    s_low = np.take_along_axis(signs, lower[..., None], axis=-1)[..., 0]
    s_high = np.take_along_axis(signs, higher[..., None], axis=-1)[..., 0]
    return 4 * axis + (s_low > 0) + 2 * (s_high > 0)


def vertex_id(signs):
    """Ids of the vertices with ``signs`` (..., 3)."""
    return ((np.asarray(signs) > 0) * np.array([1, 2, 4])).sum(axis=-1)


def _tables():
    """Per face: its corner signs in cyclic order, corner vertex ids, edge ids (corner c to
    c + 1); as a reference face: its side planes (axis, sign), the edge each meets it in, and
    the vertex where two side planes meet it (-1 for parallel planes)."""
    corners = np.zeros((6, 4, 3))
    plane_axis = np.zeros((6, 4), np.int64)
    plane_sign = np.zeros((6, 4))
    plane_edge = np.zeros((6, 4), np.int64)
    corner_vertex = np.full((6, 4, 4), -1, np.int64)
    for f in range(6):
        i, sigma = f // 2, 2 * (f % 2) - 1
        j1, j2 = (i + 1) % 3, (i + 2) % 3
        for c, (s1, s2) in enumerate([(-1, -1), (1, -1), (1, 1), (-1, 1)]):
            corners[f, c, [i, j1, j2]] = sigma, s1, s2
        plane_axis[f] = [j1, j1, j2, j2]
        plane_sign[f] = [-1, 1, -1, 1]
        for k in range(4):  # side plane k meets the face in the edge along the other side axis
            signs = np.zeros(3)
            signs[[i, plane_axis[f, k]]] = sigma, plane_sign[f, k]
            plane_edge[f, k] = edge_id(j1 + j2 - plane_axis[f, k], signs)
            for k2 in range(4):
                if k2 // 2 != k // 2:
                    signs[plane_axis[f, k2]] = plane_sign[f, k2]
                    corner_vertex[f, k, k2] = vertex_id(signs)
    # the edge from corner c to c + 1 runs along the axis where their signs differ
    nxt = np.roll(corners, -1, axis=1)
    edge = edge_id(np.argmax(corners != nxt, axis=2), corners)
    out = (corners, vertex_id(corners), edge, plane_axis, plane_sign, plane_edge, corner_vertex)
    for a in out:
        a.setflags(write=False)
    return out


(FACE_CORNERS, FACE_VERTEX_IDS, FACE_EDGE_IDS, PLANE_AXIS, PLANE_SIGN, PLANE_EDGE,
 CORNER_VERTEX) = _tables()


def clip_face(corners: np.ndarray, half: np.ndarray, ref_face: np.ndarray):
    """Clip incident rectangles against the side planes of reference faces (Sutherland-Hodgman,
    fixed buffers and masks), all in the reference box's frame.

    Args:
        corners: (m, 4, 3) incident face corners in cyclic order [m].
        half: (m, 3) half extents of the reference box [m].
        ref_face: (m,) reference face ids.

    Returns:
        (polygon (m, 8, 3) [m], count (m,), corner labels (m, 8) (see EDGE_CUT)).
    """
    m = len(corners)
    poly = np.zeros((m, CAPACITY, 3))
    poly[:, :4] = corners
    count = np.full(m, 4)
    labels = np.zeros((m, CAPACITY), np.int64)
    labels[:, :4] = np.arange(4)
    edges = labels.copy()
    rows = np.arange(m)
    slot = np.arange(CAPACITY)
    for k in range(4):
        axis = PLANE_AXIS[ref_face, k]
        sign, limit = PLANE_SIGN[ref_face, k], half[rows, axis]
        # only the polygons with a corner beyond the plane change (the others' corners all
        # count as inside, as in _clip_plane)
        d = sign[:, None] * poly[rows[:, None], slot, axis[:, None]] - limit[:, None]
        beyond = d > ON_PLANE * limit[:, None]
        out = np.flatnonzero((beyond & (slot < count[:, None])).any(axis=1))
        if not len(out):
            continue
        poly[out], count[out], labels[out], edges[out] = _clip_plane(
            poly[out], count[out], labels[out], edges[out], axis[out], sign[out], limit[out], k)
    return poly, count, labels


def _clip_plane(poly, count, labels, edges, axis, sign, limit, plane):
    """Keep the part of each polygon with sign * x[axis] <= limit; new corners are labelled by
    the edge they cut and ``plane``, the new edge along the plane by ``plane``."""
    m = len(poly)
    slot = np.arange(CAPACITY)
    live = slot < count[:, None]
    nxt = (slot + 1) % np.maximum(count, 1)[:, None]
    d = sign[:, None] * poly[np.arange(m)[:, None], slot, axis[:, None]] - limit[:, None]
    # a corner within ON_PLANE of the half extent counts as inside: an incident edge lying
    # on the plane (aligned boxes in a stack) is kept whole instead of being cut at a point
    # that rounding places anywhere along it
    d = np.where(np.abs(d) <= ON_PLANE * limit[:, None], 0.0, d)
    d_next = np.take_along_axis(d, nxt, axis=1)
    inside = d <= 0.0
    keep = live & inside
    cut = live & (inside != np.take_along_axis(inside, nxt, axis=1))
    frac = d / np.where(cut, d - d_next, 1.0)
    p_next = np.take_along_axis(poly, nxt[..., None], axis=1)
    x = poly + frac[..., None] * (p_next - poly)
    n_out = keep.astype(np.int64) + cut
    start = np.cumsum(n_out, axis=1) - n_out
    out_poly, out_labels, out_edges = np.zeros_like(poly), np.zeros_like(labels), \
        np.zeros_like(edges)
    r, c = np.nonzero(keep)
    out_poly[r, start[r, c]] = poly[r, c]
    out_labels[r, start[r, c]] = labels[r, c]
    out_edges[r, start[r, c]] = edges[r, c]
    r, c = np.nonzero(cut)
    pos = start[r, c] + keep[r, c]
    fits = pos < CAPACITY  # rounding on a degenerate polygon may add a spurious pair of cuts
    r, c, pos = r[fits], c[fits], pos[fits]
    e = edges[r, c]
    out_poly[r, pos] = x[r, c]
    out_labels[r, pos] = np.where(e < 4, EDGE_CUT + 4 * e, PLANE_CORNER + 4 * (e - 4)) + plane
    # leaving through the plane: the next edge runs along it; entering: still the cut edge
    out_edges[r, pos] = np.where(keep[r, c], 4 + plane, e)
    return out_poly, np.minimum(n_out.sum(axis=1), CAPACITY), out_labels, out_edges


def point_ids(labels, inc_face, ref_face, ref_is_a):
    """Persistent ids (m, 8) of clipped corners (see the module docstring).

    Args:
        labels: (m, 8) clip labels. inc_face, ref_face: (m,) face ids on the incident and the
            reference box. ref_is_a: (m,) bool, the reference face belongs to box A.
    """
    inc, ref, on_a = inc_face[:, None], ref_face[:, None], ref_is_a[:, None]
    corner = np.clip(labels, 0, 3)
    v_inc = FACE_VERTEX_IDS[inc, corner]
    cut = np.clip(labels - EDGE_CUT, 0, 15)
    e_inc, e_ref = FACE_EDGE_IDS[inc, cut // 4], PLANE_EDGE[ref, cut % 4]
    planes = np.clip(labels - PLANE_CORNER, 0, 15)
    v_ref = CORNER_VERTEX[ref, planes // 4, planes % 4]
    vertex_on_face = np.where(on_a, FACE_VERTEX + 8 * ref + v_inc, VERTEX_FACE + 6 * v_inc + ref)
    edge_cross = EDGE_EDGE + np.where(on_a, 12 * e_ref + e_inc, 12 * e_inc + e_ref)
    face_on_vertex = np.where(on_a, VERTEX_FACE + 6 * v_ref + inc, FACE_VERTEX + 8 * inc + v_ref)
    return np.where(labels < EDGE_CUT, vertex_on_face,
                    np.where(labels < PLANE_CORNER, edge_cross, face_on_vertex))


def reduce_points(p: np.ndarray, sep: np.ndarray, valid: np.ndarray, axis: np.ndarray,
                  tie: np.ndarray) -> np.ndarray:
    """At most 4 of the valid points of each row, spread widely: the deepest, the one farthest
    from it, the one making the largest triangle with those two, and the one adding the most
    area to that triangle. Near-ties go to the lowest slot (the clip's order is deterministic),
    so that rounding does not make the choice jump between frames or between A/B orders.

    Args:
        p: (m, 8, 3) points [m]. sep: (m, 8) separations [m]. valid: (m, 8) bool.
        axis: (m,) reference normal axis (areas are measured about it).
        tie: (m,) depths closer than this [m] count as equally deep.

    Returns:
        (m, 8) bool: the kept points.
    """
    rows = np.arange(len(p))
    chosen = np.zeros(valid.shape, dtype=bool)
    deepest = np.min(np.where(valid, sep, np.inf), axis=1)
    first = np.argmax(valid & (sep <= (deepest + tie)[:, None]), axis=1)
    chosen[rows, first] = True
    p1 = p[rows, first][:, None]
    second = _first_largest(np.einsum("mki,mki->mk", p - p1, p - p1), valid & ~chosen)
    chosen[rows, second] = True
    p2 = p[rows, second][:, None]

    def area(u, v):  # signed areas (m, 8) of triangles (u, v, p) about the axis
        return cross(v - u, p - u)[rows, :, axis]

    a12 = area(p1, p2)
    third = _first_largest(np.abs(a12), valid & ~chosen)
    chosen[rows, third] = True
    p3 = p[rows, third][:, None]
    turn = -np.sign(a12[rows, third])[:, None]  # outside an edge of the triangle (p1, p2, p3)
    added = np.maximum(np.maximum(turn * a12, turn * area(p2, p3)), turn * area(p3, p1))
    chosen[rows, _first_largest(added, valid & ~chosen)] = True
    return chosen & valid


def _first_largest(values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Per row, the first slot of ``mask`` whose value is within 1e-9 (relative) of the row's
    largest (m,); rows with an empty mask give some slot, dropped by the caller's mask."""
    best = np.max(np.where(mask, values, -np.inf), axis=1, keepdims=True)
    return np.argmax(mask & (values >= best - 1e-9 * np.abs(best)), axis=1)
