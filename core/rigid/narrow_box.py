"""Box-box contact manifolds: separating axes, then a clipped face or one edge-edge point.

Separating axes (Gottschalk's 15, as in :mod:`..collision.sat`, evaluated in A's frame): the 3
face normals of each box and the 9 cross products of an edge direction of A with one of B
(skipped when the edges are parallel: the axis is then rounding). The axis of largest
separation wins, with a preference for faces: B's face only when it separates more than A's by
FACE_SLACK, an edge axis only when it beats the best face by EDGE_SLACK (relative) plus
EDGE_SLACK_ABS (times the smaller box's size), so that boxes resting on each other do not
flicker between face and edge contacts.

Face axis: the reference face is the owner's face towards the other box, the incident face the
other box's face most anti-parallel to it. The incident face is clipped against the reference
face's side planes (:mod:`.narrow_clip`); corners whose separation (height above the reference
face) is below the margin are kept, at most 4 (:func:`.narrow_clip.reduce_points`), each
reported midway between the incident point and its foot on the reference face. For a vertex of
the incident face that lies over the reference face (the closest features of separated boxes,
or the deepest vertex of resting ones) the separation is exact; no point is deeper than the
boxes' projections along the normal overlap. When the clip keeps nothing although the axis
separation is within the margin (boxes meeting corner to side, off the reference face), the
incident face's lowest corner is kept alone, with the axis separation.

Edge axis: one point midway between the closest points of the two supporting edges, with the
axis' separation (exact when those closest points lie inside both edges).
"""
from __future__ import annotations

import numpy as np

from ..transforms import cross
from .narrow_base import PairContacts, as_margin, closest_segments, collect, unit, world
from .narrow_clip import (CAPACITY, EDGE_EDGE, FACE_CORNERS, clip_face, edge_id, point_ids,
                          reduce_points)

FACE_SLACK = 1e-6  # relative to the smaller box's size
EDGE_SLACK = 0.05  # relative to the best face separation
EDGE_SLACK_ABS = 1e-4  # relative to the smaller box's size
DEEPEST_TIE = 1e-10  # relative to the smaller box's size: deepest clip points that tie
PARALLEL_EDGES = 1e-6  # |a_i x b_j| below which the edge axis is skipped

# the 9 edge-edge axes a_i x b_j (flat index 3 i + j) and the cyclic successors of i and j
_I = np.repeat(np.arange(3), 3)
_J = np.tile(np.arange(3), 3)
_I1, _I2 = (_I + 1) % 3, (_I + 2) % 3
_J1, _J2 = (_J + 1) % 3, (_J + 2) % 3


def box_box(ca, Ra, ha, cb, Rb, hb, margin) -> PairContacts:
    """Box A against box B: at most 4 points per pair (see the module docstring).

    Args:
        ca, cb: (m, 3) centres [m]. Ra, Rb: (m, 3, 3) rotations (columns: the box axes).
        ha, hb: (m, 3) half extents [m].
        margin: scalar or (m,) speculative distance [m].
    """
    ca, Ra, ha, cb, Rb, hb = (np.asarray(x, dtype=np.float64) for x in (ca, Ra, ha, cb, Rb, hb))
    m = len(ca)
    margin = as_margin(margin, m)
    rel = np.swapaxes(Ra, 1, 2) @ Rb  # rel[i, j] = a_i . b_j
    t = np.einsum("mji,mj->mi", Ra, cb - ca)  # B's centre in A's frame
    face_a, face_b, edge = _separations(rel, t, ha, hb)
    size = np.minimum(ha.max(axis=1), hb.max(axis=1))
    rows = np.arange(m)
    ia, jb, ke = face_a.argmax(axis=1), face_b.argmax(axis=1), edge.argmax(axis=1)
    sep_a, sep_b, sep_e = face_a[rows, ia], face_b[rows, jb], edge[rows, ke]
    use_b = sep_b > sep_a + FACE_SLACK * size
    sep_face = np.where(use_b, sep_b, sep_a)
    use_edge = sep_e > sep_face + EDGE_SLACK * np.abs(sep_face) + EDGE_SLACK_ABS * size
    near = np.maximum(sep_face, sep_e) < margin
    f = np.nonzero(near & ~use_edge)[0]
    e = np.nonzero(near & use_edge)[0]
    frames = (ca, Ra, ha, cb, Rb, hb)
    faces = _face_contacts(f, *(x[f] for x in frames), rel[f], t[f], use_b[f], ia[f], jb[f],
                           margin[f], size[f])
    edges = _edge_contacts(e, *(x[e] for x in frames[:3]), hb[e], rel[e], t[e], ke[e], sep_e[e])
    return PairContacts.concatenate([faces, edges])


def _separations(rel, t, ha, hb):
    """Separations [m] along A's face axes (m, 3), B's (m, 3) and the edge axes a_i x b_j
    (m, 9), flat 3 i + j; -inf for skipped (parallel) edge axes."""
    abs_rel = np.abs(rel)
    face_a = np.abs(t) - ha - np.einsum("mij,mj->mi", abs_rel, hb)
    t_b = np.einsum("mi,mij->mj", t, rel)
    face_b = np.abs(t_b) - hb - np.einsum("mi,mij->mj", ha, abs_rel)
    r, ar = rel.reshape(-1, 9), abs_rel.reshape(-1, 9)
    reach_a = ha[:, _I1] * ar[:, 3 * _I2 + _J] + ha[:, _I2] * ar[:, 3 * _I1 + _J]
    reach_b = hb[:, _J1] * ar[:, 3 * _I + _J2] + hb[:, _J2] * ar[:, 3 * _I + _J1]
    dist = np.abs(t[:, _I2] * r[:, 3 * _I1 + _J] - t[:, _I1] * r[:, 3 * _I2 + _J])
    length = np.sqrt(np.maximum(1.0 - r[:, 3 * _I + _J] ** 2, 0.0))  # |a_i x b_j|
    ok = length > PARALLEL_EDGES
    edge = np.where(ok, (dist - reach_a - reach_b) / np.where(ok, length, 1.0), -np.inf)
    return face_a, face_b, edge


def _face_contacts(idx, ca, Ra, ha, cb, Rb, hb, rel, t, use_b, ia, jb, margin, size):
    """Clipped face manifolds of pairs ``idx`` (see the module docstring): everything in the
    frame of the reference box Y; X is the incident box."""
    if not len(idx):
        return PairContacts.empty()
    m = len(idx)
    rows = np.arange(m)
    ref_a = ~use_b
    axis = np.where(ref_a, ia, jb)
    t_b = -np.einsum("mi,mij->mj", t, rel)  # A's centre in B's frame
    towards = np.where(ref_a, t[rows, ia], t_b[rows, jb])  # X's centre along Y's axis
    sigma = np.where(towards < 0.0, -1.0, 1.0)
    ref_face = 2 * axis + (sigma > 0)
    rot = np.where(ref_a[:, None, None], rel, np.swapaxes(rel, 1, 2))  # X's axes in Y's frame
    t_x = np.where(ref_a[:, None], t, t_b)
    h_x, h_y = np.where(ref_a[:, None], hb, ha), np.where(ref_a[:, None], ha, hb)
    c_y, r_y = np.where(ref_a[:, None], ca, cb), np.where(ref_a[:, None, None], Ra, Rb)
    facing = rot[rows, axis]  # each X axis along Y's reference axis
    inc_axis = np.abs(facing).argmax(axis=1)
    inc_face = 2 * inc_axis + (sigma * facing[rows, inc_axis] < 0.0)
    corners = t_x[:, None] + np.einsum("mij,mcj->mci", rot, FACE_CORNERS[inc_face] * h_x[:, None])
    poly, count, labels = clip_face(corners, h_y, ref_face)
    sep = sigma[:, None] * poly[rows, :, axis] - h_y[rows, axis][:, None]
    valid = (np.arange(CAPACITY) < count[:, None]) & (sep < margin[:, None])
    # the clip may leave nothing within the margin while the axis says the pair is near (an
    # incident corner beyond the reference face's sides): keep X's lowest corner, whose height
    # is the axis separation, so that speculative contact still stops the approach
    height = sigma[:, None] * corners[rows, :, axis] - h_y[rows, axis][:, None]
    lowest = height.argmin(axis=1)
    lone = np.nonzero(~valid.any(axis=1) & (height[rows, lowest] < margin))[0]
    poly[lone, 0], sep[lone, 0] = corners[lone, lowest[lone]], height[lone, lowest[lone]]
    labels[lone, 0], valid[lone, 0] = lowest[lone], True
    many = np.nonzero(valid.sum(axis=1) > 4)[0]
    if len(many):
        valid[many] = reduce_points(poly[many], sep[many], valid[many], axis[many],
                                    DEEPEST_TIE * size[many])
    foot = poly.copy()
    foot[rows, :, axis] -= 0.5 * sigma[:, None] * sep  # midway down to the reference face
    point = c_y[:, None] + world(r_y, foot)
    u = sigma[:, None] * r_y[rows, :, axis]  # reference face normal, towards X
    normal = np.where(ref_a[:, None], u, -u)
    feature = point_ids(labels, inc_face, ref_face, ref_a)
    return collect(idx, point, normal, sep, feature, valid)


def _edge_contacts(idx, ca, Ra, ha, hb, rel, t, axis, sep):
    """One point per pair ``idx`` between the supporting edges of the edge axis a_i x b_j
    (flat index ``axis``) with that axis' separation ``sep``; in A's frame."""
    if not len(idx):
        return PairContacts.empty()
    m = len(idx)
    rows = np.arange(m)
    i, j = axis // 3, axis % 3
    dir_a = np.eye(3)[i]
    dir_b = rel[rows, :, j]
    n, _ = unit(cross(dir_a, dir_b), dir_a)
    n *= np.where(np.einsum("mi,mi->m", n, t) < 0.0, -1.0, 1.0)[:, None]  # from A towards B
    sign_a = np.where(n < 0.0, -1.0, 1.0)  # A's edge farthest along n
    sign_a[rows, i] = 0.0
    sign_b = np.where(np.einsum("mij,mi->mj", rel, n) > 0.0, -1.0, 1.0)  # B's farthest back
    sign_b[rows, j] = 0.0
    mid_a = sign_a * ha
    mid_b = t + np.einsum("mij,mj->mi", rel, sign_b * hb)
    s, u = closest_segments(mid_a, dir_a, ha[rows, i], mid_b, dir_b, hb[rows, j])
    point = ca + world(Ra, 0.5 * (mid_a + s[:, None] * dir_a + mid_b + u[:, None] * dir_b))
    feature = EDGE_EDGE + 12 * edge_id(i, sign_a) + edge_id(j, sign_b)
    return collect(idx, point[:, None], world(Ra, n), sep[:, None], feature[:, None],
                   np.ones((m, 1), dtype=bool))
