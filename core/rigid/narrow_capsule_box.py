"""Capsule-box contacts: the exact closest points of the capsule's axis segment and the box, and
a face clip for a capsule lying on a face. Everything is computed in the box's frame.

While the segment stays outside the box (the capsule overlaps less than its radius) the closest
points are exact: the squared distance from the segment to the box is a convex, piecewise
quadratic function of the segment parameter, with pieces bounded where the segment crosses a
slab of the box (6 knots); the minimum of each of the 7 pieces is closed-form.

* Closest box point on a face (one coordinate beyond the box): the capsule meets that face.
  The segment is clipped to the face's slab (the prism over the face) and both ends of the
  clipped part are candidates, with the face normal and their heights above the face. The
  height is linear along the segment and at least the distance wherever the segment lies over
  the face, so the lower end's separation is exactly the capsule's distance.
* Closest box point on an edge or a vertex: one point at the closest points.

A segment that enters the box (overlap deeper than the radius) is pushed out along the best
of 6 separating axes (the box's face normals, and the segment direction crossed with each box
edge direction, as for two boxes); a face axis then gives the face clip, an edge axis one point
between the segment and the supporting box edge.

Feature ids: 2 face + (0 low, 1 high end of the clipped part) in [0, 12); closest points on an
edge or a vertex region 12 + 3 (box region, base 3 per axis) + segment region in [12, 93);
an edge axis 93 + box edge in [93, 105).
"""
from __future__ import annotations

import numpy as np

from ..transforms import cross
from .narrow_base import (PairContacts, as_margin, closest_segments, collect, local, region,
                          unit, world)
from .narrow_box import EDGE_SLACK, EDGE_SLACK_ABS, PARALLEL_EDGES
from .narrow_clip import edge_id

TOUCH = 1e-9  # relative to the pair's size: closer than this, the segment counts as inside
BEYOND = 1e-10  # relative to the pair's size: a coordinate this far past the box is beyond it
_REGION_IDS, _EDGE_IDS = 12, 93


def capsule_box(cc, Rc, rc, lc, cb, Rb, hb, margin) -> PairContacts:
    """Capsule A against box B: up to 2 points per pair (see the module docstring).

    Args:
        cc: (m, 3) capsule centres [m]. Rc: (m, 3, 3) rotations (axis: local Z).
        rc, lc: (m,) radii and half lengths [m].
        cb: (m, 3) box centres [m]. Rb: (m, 3, 3) rotations. hb: (m, 3) half extents [m].
        margin: scalar or (m,) speculative distance [m].
    """
    cc, Rc, rc, lc, cb, Rb, hb = (np.asarray(x, dtype=np.float64)
                                  for x in (cc, Rc, rc, lc, cb, Rb, hb))
    m = len(cc)
    p0, d = local(Rb, cc - cb), local(Rb, Rc[:, :, 2])
    size = hb.max(axis=1) + lc
    s = _closest_param(p0, d, lc, hb)
    x = p0 + s[:, None] * d
    q = np.clip(x, -hb, hb)
    out, dist = unit(x - q, d)  # from the box towards the segment
    inside = dist <= TOUCH * size
    gap, on_face, axis, out_sat = _push_out(p0, d, lc, hb, size)
    # which face the capsule meets, if any: the closest box point's, or the push-out axis'
    beyond = np.abs(x) - hb > BEYOND * size[:, None]
    face = np.where(inside, on_face, beyond.sum(axis=1) == 1)
    face_axis = np.where(inside, axis, beyond.argmax(axis=1))
    side = np.sign(np.where(inside[:, None], out_sat, x)[np.arange(m), face_axis])
    side = np.where(side == 0.0, 1.0, side)
    f_point, f_sep, f_out, f_feature, two = _face_points(p0, d, lc, rc, hb, s, face_axis, side)
    # otherwise one point: the closest points, or the segment against the supporting box edge
    e_point, e_sep, e_feature = _edge_point(p0, d, lc, rc, hb, axis, out_sat, gap)
    region_id = ((np.sign(x - q) + 1.0) @ [1.0, 3.0, 9.0]).astype(np.int64)  # per axis: -, 0, +
    one_point = np.where(inside[:, None], e_point, 0.5 * (q + x - rc[:, None] * out))
    one_sep = np.where(inside, e_sep, dist - rc)
    one_feature = np.where(inside, e_feature, _REGION_IDS + 3 * region_id + region(s, lc))
    one_out = np.where(inside[:, None], out_sat, out)
    point = np.where(face[:, None, None], f_point, one_point[:, None])
    sep = np.where(face[:, None], f_sep, one_sep[:, None])
    feature = np.where(face[:, None], f_feature, one_feature[:, None])
    normal = -world(Rb, np.where(face[:, None], f_out, one_out))
    keep = (sep < as_margin(margin, m)[:, None]) & np.stack([np.ones(m, bool), face & two], 1)
    return collect(np.arange(m), cb[:, None] + world(Rb, point), normal, sep, feature, keep)


def _closest_param(p0, d, half, h) -> np.ndarray:
    """Parameter s (m,) in [-half, half] of the point of segment p0 + s d nearest to the box
    |x| <= h (all (m, 3), box frame): the minimum over the pieces between the knots where the
    segment crosses the box's slabs (see the module docstring)."""
    moving = d != 0.0
    inv = 1.0 / np.where(moving, d, 1.0)
    cross = np.concatenate([np.where(moving, (-h - p0) * inv, -half[:, None]),
                            np.where(moving, (h - p0) * inv, -half[:, None])], axis=1)
    knots = np.sort(np.concatenate([-half[:, None], np.clip(cross, -half[:, None],
                                                            half[:, None]), half[:, None]],
                                   axis=1), axis=1)
    lo, hi = knots[:, :-1], knots[:, 1:]
    mid = 0.5 * (lo + hi)
    x = p0[:, None] + mid[..., None] * d[:, None]
    above, below = x > h[:, None], x < -h[:, None]
    offset = np.where(above, (p0 - h)[:, None], np.where(below, (p0 + h)[:, None], 0.0))
    slope = np.where(above | below, d[:, None], 0.0)
    a = np.einsum("mki,mki->mk", slope, slope)
    b = np.einsum("mki,mki->mk", slope, offset)
    s = np.clip(np.where(a > 0.0, -b / np.where(a > 0.0, a, 1.0), mid), lo, hi)
    y = p0[:, None] + s[..., None] * d[:, None]
    excess = np.maximum(np.abs(y) - h[:, None], 0.0)
    best = np.einsum("mki,mki->mk", excess, excess).argmin(axis=1)
    return s[np.arange(len(s)), best]


def _push_out(p0, d, half, h, size):
    """Separating axes of a segment that meets the box: the 3 face normals and d x e_k.

    Returns:
        (gap (m,) [m] along the best axis (negative), on_face (m,) bool, axis (m,) the face or
        edge axis index, direction (m, 3) unit, from the box towards the segment).
    """
    m = len(p0)
    rows = np.arange(m)
    face = np.abs(p0) - half[:, None] * np.abs(d) - h
    axes = cross(d[:, None, :], np.eye(3)[None])  # (m, 3 edge axes, 3)
    length = np.linalg.norm(axes, axis=2)
    ok = length > PARALLEL_EDGES
    along = np.einsum("mki,mi->mk", axes, p0)
    reach = np.einsum("mki,mi->mk", np.abs(axes), h)
    edge = np.where(ok, (np.abs(along) - reach) / np.where(ok, length, 1.0), -np.inf)
    i, k = face.argmax(axis=1), edge.argmax(axis=1)
    sep_face, sep_edge = face[rows, i], edge[rows, k]
    use_edge = sep_edge > sep_face + EDGE_SLACK * np.abs(sep_face) + EDGE_SLACK_ABS * size
    face_dir = np.zeros((m, 3))
    face_dir[rows, i] = np.where(p0[rows, i] < 0.0, -1.0, 1.0)
    edge_dir = axes[rows, k] / np.where(ok[rows, k], length[rows, k], 1.0)[:, None]
    edge_dir *= np.where(along[rows, k] < 0.0, -1.0, 1.0)[:, None]
    direction = np.where(use_edge[:, None], edge_dir, face_dir)
    return (np.where(use_edge, sep_edge, sep_face), ~use_edge, np.where(use_edge, k, i),
            direction)


def _edge_point(p0, d, half, radius, h, k, out, gap):
    """Point (m, 3), separation (m,) and feature (m,) between the segment and the box edge
    along axis k supporting the box in direction ``out`` (towards the segment)."""
    rows = np.arange(len(p0))
    signs = np.where(out < 0.0, -1.0, 1.0)
    signs[rows, k] = 0.0
    centre = signs * h
    along = np.eye(3)[k]
    s, t = closest_segments(p0, d, half, centre, along, h[rows, k])
    p = p0 + s[:, None] * d - radius[:, None] * out
    e = centre + t[:, None] * along
    return 0.5 * (p + e), gap - radius, _EDGE_IDS + edge_id(k, signs)


def _face_points(p0, d, half, radius, h, s_best, axis, side):
    """Both ends of the segment's part over the face (axis, side) (side: -1 or +1).

    Returns:
        (points (m, 2, 3) [m], separations (m, 2) [m], the face's outward normal (m, 3),
        feature ids (m, 2), whether the second end is a distinct point (m,)).
    """
    m = len(p0)
    rows = np.arange(m)
    lo, hi = -half.copy(), half.copy()
    for j in range(3):  # the two side slabs of the face
        moving = (axis != j) & (d[:, j] != 0.0)
        inv = 1.0 / np.where(moving, d[:, j], 1.0)
        a, b = (-h[:, j] - p0[:, j]) * inv, (h[:, j] - p0[:, j]) * inv
        lo = np.where(moving, np.maximum(lo, np.minimum(a, b)), lo)
        hi = np.where(moving, np.minimum(hi, np.maximum(a, b)), hi)
    empty = lo > hi  # only by rounding: the closest point lies over the face
    lo, hi = np.where(empty, s_best, lo), np.where(empty, s_best, hi)
    x = p0[:, None] + np.stack([lo, hi], axis=1)[..., None] * d[:, None]
    height = side[:, None] * x[rows, :, axis] - h[rows, axis][:, None]
    x[rows, :, axis] -= 0.5 * side[:, None] * (height + radius[:, None])  # midway
    normal = np.zeros((m, 3))
    normal[rows, axis] = side
    feature = 2 * (2 * axis + (side > 0))[:, None] + np.arange(2)
    return x, height - radius[:, None], normal, feature, hi > lo
