"""Rigid narrow phase: contact points between convex shapes, vectorised over all pairs of a kind.

Each function takes m pairs of one kind in world space and returns a :class:`PairContacts`:
points midway between the surfaces, unit normals from A towards B, signed separations along the
normal and persistent feature ids. Shapes:

* sphere: centre c (m, 3) [m], radius r (m,) [m];
* box: centre c (m, 3), rotation R (m, 3, 3) (columns: the box's axes in world), half extents
  h (m, 3) [m];
* capsule: centre c, rotation R, radius r (m,), half length l (m,) of its axis segment along
  the local Z axis (from c - l R[:, :, 2] to c + l R[:, :, 2]) [m].

Speculative contacts: a point is reported when its separation is below ``margin`` (scalar or
(m,) [m]), also while the shapes are still apart, so that a solver can let bodies close the gap
but no further; pairs farther apart than the margin give no points.

Rounded shapes (spheres, capsules) reduce to the closest points of their cores (a point or a
segment) and are exact. Boxes use separating axes and clipping (:mod:`.narrow_box`); capsules
against boxes the exact segment-box distance with a face clip (:mod:`.narrow_capsule_box`).
"""
from __future__ import annotations

import numpy as np

from ..transforms import cross
from .narrow_base import (PARALLEL_SQ, PairContacts, as_margin, closest_segments, collect, dot,
                          local, perpendicular, region, round_pair, unit, world)
from .narrow_box import box_box
from .narrow_capsule_box import capsule_box

__all__ = ["PairContacts", "box_box", "capsule_box", "capsule_capsule", "capsule_sphere",
           "sphere_box", "sphere_sphere"]

# Capsules whose axes make an angle with a sine below this lie alongside each other: they touch
# along a line, and a second point at the far end of their common stretch keeps them from rocking.
ALONGSIDE_SIN = 0.02
# ... provided that common stretch is longer than this fraction of their half lengths.
ALONGSIDE_OVERLAP = 1e-6
_UP = np.array([0.0, 0.0, 1.0])


def _f(*arrays) -> list[np.ndarray]:
    """The inputs as float64 arrays."""
    return [np.asarray(a, dtype=np.float64) for a in arrays]


def _single(n, sep, point, feature, margin) -> PairContacts:
    """One candidate point per pair, kept where its separation is below the margin."""
    return collect(np.arange(len(sep)), point[:, None], n, sep[:, None], feature[:, None],
                   (sep < margin)[:, None])


def sphere_sphere(ca, ra, cb, rb, margin) -> PairContacts:
    """Sphere A against sphere B: at most one point per pair.

    Args:
        ca, cb: (m, 3) centres [m]. ra, rb: (m,) radii [m].
        margin: scalar or (m,) speculative distance [m].
    """
    ca, ra, cb, rb = _f(ca, ra, cb, rb)
    n, sep, point = round_pair(ca, ra, cb, rb, _UP)  # coincident centres: any normal will do
    return _single(n, sep, point, np.zeros(len(ca), np.int64), as_margin(margin, len(ca)))


def sphere_box(cs, rs, cb, Rb, hb, margin) -> PairContacts:
    """Sphere A against box B: at most one point per pair.

    A centre outside the box meets its closest box point; a centre inside leaves through the
    nearest face. The feature id (in [0, 27)) is the box feature: per axis below, within or
    above the box, base 3 (a centre inside counts as at the face it leaves through, so a sphere
    sinking into a face keeps its id).

    Args:
        cs: (m, 3) sphere centres [m]. rs: (m,) radii [m].
        cb: (m, 3) box centres [m]. Rb: (m, 3, 3) box rotations. hb: (m, 3) half extents [m].
        margin: scalar or (m,) speculative distance [m].
    """
    cs, rs, cb, Rb, hb = _f(cs, rs, cb, Rb, hb)
    m = len(cs)
    p = local(Rb, cs - cb)
    q = np.clip(p, -hb, hb)
    side = np.sign(p - q)  # per axis: -1 below, 0 within, +1 above the box
    out = (side != 0.0).any(axis=1)
    u_out, dist = unit(p - q, _UP)
    depth = hb - np.abs(p)  # inside: how far each face pair is
    k = np.argmin(depth, axis=1)
    rows = np.arange(m)
    face_sign = np.where(p[rows, k] >= 0.0, 1.0, -1.0)
    u_in = np.zeros((m, 3))
    u_in[rows, k] = face_sign
    q_in = p.copy()
    q_in[rows, k] = face_sign * hb[rows, k]
    u = np.where(out[:, None], u_out, u_in)  # box outward normal at the box point (local)
    q = np.where(out[:, None], q, q_in)
    side = np.where(out[:, None], side, u_in)
    gap = np.where(out, dist, -depth[rows, k])  # signed distance of the centre from the box
    n = -world(Rb, u)
    sep = gap - rs
    point = 0.5 * (cb + world(Rb, q) + cs + rs[:, None] * n)
    feature = ((side + 1.0) @ np.array([1.0, 3.0, 9.0])).astype(np.int64)
    return _single(n, sep, point, feature, as_margin(margin, m))


def capsule_sphere(cc, Rc, rc, lc, cs, rs, margin) -> PairContacts:
    """Capsule A against sphere B: at most one point per pair; the feature id (0, 1, 2) says
    whether the sphere meets the low cap, the side or the high cap.

    Args:
        cc: (m, 3) capsule centres [m]. Rc: (m, 3, 3) rotations (axis: local Z).
        rc, lc: (m,) radii and half lengths [m].
        cs: (m, 3) sphere centres [m]. rs: (m,) radii [m].
        margin: scalar or (m,) speculative distance [m].
    """
    cc, Rc, rc, lc, cs, rs = _f(cc, Rc, rc, lc, cs, rs)
    axis = Rc[:, :, 2]
    s = np.clip(dot(cs - cc, axis), -lc, lc)
    # a centre on the axis: leave sideways (local X), the shortest way out of the capsule
    n, sep, point = round_pair(cc + s[:, None] * axis, rc, cs, rs, Rc[:, :, 0])
    return _single(n, sep, point, region(s, lc), as_margin(margin, len(cc)))


def capsule_capsule(ca, Ra, ra, la, cb, Rb, rb, lb, margin) -> PairContacts:
    """Capsule A against capsule B: one point at the closest points of the axis segments, and
    a second one when the capsules lie alongside each other (axes within ALONGSIDE_SIN, with a
    common stretch): then the points sit at the two ends of that stretch (or at the closest
    points and the far end of the stretch, when the axes are not exactly parallel), all with the
    normal of the closest points. As every point of A lies behind, and every point of B beyond,
    the planes through the closest points, the second point never separates less than the first.

    Feature ids: 3 region(A) + region(B) (low end, inside, high end of each segment) for a
    single point; 9 and 10 for the low and high end of the common stretch when alongside.

    Args:
        ca, cb: (m, 3) centres [m]. Ra, Rb: (m, 3, 3) rotations (axis: local Z).
        ra, rb, la, lb: (m,) radii and half lengths [m].
        margin: scalar or (m,) speculative distance [m].
    """
    ca, Ra, ra, la, cb, Rb, rb, lb = _f(ca, Ra, ra, la, cb, Rb, rb, lb)
    m = len(ca)
    a, b = Ra[:, :, 2], Rb[:, :, 2]
    s, t = closest_segments(ca, a, la, cb, b, lb)
    pa, pb = ca + s[:, None] * a, cb + t[:, None] * b
    across, sine = unit(cross(a, b), _UP)
    fallback = np.where((sine > np.sqrt(PARALLEL_SQ))[:, None], across, perpendicular(a))
    fallback *= np.where(dot(cb - ca, fallback) < 0.0, -1.0, 1.0)[:, None]
    n, sep, point = round_pair(pa, ra, pb, rb, fallback)
    feature = 3 * region(s, la) + region(t, lb)
    alongside, (lo, hi), far_hi, exact = _common_stretch(ca, a, la, cb, b, lb, 0.5 * (pa + pb))
    end_sep, end_point = [], []
    for v in (lo, hi):
        p_end = ca + np.clip(v[0], -la, la)[:, None] * a
        q_end = cb + np.clip(v[1], -lb, lb)[:, None] * b
        end_sep.append(dot(q_end - p_end, n) - ra - rb)
        end_point.append(0.5 * (p_end + q_end) + (0.5 * (ra - rb))[:, None] * n)
    # exactly parallel: both ends; otherwise the closest points and the far end
    first_sep = np.where(exact, end_sep[0], sep)
    first_point = np.where(exact[:, None], end_point[0], point)
    second_sep = np.where(far_hi, end_sep[1], end_sep[0])
    second_point = np.where(far_hi[:, None], end_point[1], end_point[0])
    first_feature = np.where(alongside, np.where(far_hi, 9, 10), feature)
    margin = as_margin(margin, m)
    return collect(np.arange(m), np.stack([first_point, second_point], axis=1), n,
                   np.stack([first_sep, second_sep], axis=1),
                   np.stack([first_feature, np.where(far_hi, 10, 9)], axis=1),
                   np.stack([first_sep < margin, alongside & (second_sep < margin)], axis=1))


def _common_stretch(ca, a, la, cb, b, lb, middle):
    """Where capsules lying alongside share their length: the overlap of both segments'
    projections on the bisector of their axes (A and B play the same part).

    Returns:
        (alongside (m,) bool, ((s, t) at the low end, (s, t) at the high end), far_hi (m,) bool:
        the high end lies farther from ``middle`` (the closest points), exact (m,) bool: the
        axes are parallel to rounding (``far_hi`` is then True and both ends are used)).
    """
    ab = dot(a, b)
    sgn = np.where(ab < 0.0, -1.0, 1.0)
    w, _ = unit(a + sgn[:, None] * b, a)
    wa, wb = dot(a, w), np.abs(dot(b, w))  # B's parameter t runs along w as sgn t
    cb_w = dot(cb - ca, w)
    lo = np.maximum(-la * wa, cb_w - lb * wb)
    hi = np.minimum(la * wa, cb_w + lb * wb)
    sine_sq = 1.0 - ab * ab
    alongside = (sine_sq < ALONGSIDE_SIN ** 2) & (hi - lo > ALONGSIDE_OVERLAP * (la + lb))
    wa_safe, wb_safe = np.where(alongside, wa, 1.0), np.where(alongside, wb, 1.0)
    ends = [(v / wa_safe, sgn * (v - cb_w) / wb_safe) for v in (lo, hi)]
    v_mid = dot(middle - ca, w)
    exact = sine_sq <= PARALLEL_SQ
    far_hi = exact | (hi - v_mid > v_mid - lo)
    return alongside, ends, far_hi, exact & alongside
