"""Colliders against a system's faces and edges: what collisions of points cannot see. A sphere
smaller than a mesh's faces, a cone's tip or a rod's edge passes between a mesh's vertices
without any vertex entering it; here the collider's corners and round parts
(:class:`~.path.Features`) are kept off the mesh's triangles and its creased edges off the
mesh's edges.

Per collider, in its local frame (a moving collider becomes a still one, as for points):

1. detect: pairs (corner or sphere, triangle) and (crease, edge) whose boxes over the
   sub-step overlap, then those apart by less than the contact gap at its end or that
   crossed during it (continuous tests, :mod:`..collision.crossing`; with :class:`NearPairs`,
   a detection after a separating round tests again only the pairs with a moved point);
2. separate: each pair's gap restored by moving the mesh's corners along the pair's normal,
   in proportion to their inverse mass and their weight in the nearest point (the impulse
   that moves the nearest point by exactly the shortfall); Gauss-Seidel passes over groups
   of pairs that share no moving point (:func:`..colouring.colour`) until every pair is
   within TOLERANCE, then detect again (a moved face may meet another part of a feature).
   A face that went through a whole sphere in the sub-step (its centre now beyond the face)
   is not pushed back across it, which would move its points further than the sphere is
   wide and could sweep a neighbouring face through it: its points go back to where they
   started in the collider's frame (as in 4), then detection runs again;
3. respond: the nearest point's approach to the collider cancelled (a bounce of restitution
   times it when faster than the rest speed), Coulomb friction on its sliding, spread over
   the corners the same way;
4. fail safe: when the rounds run out with pairs still crossed, their points go back to
   where they started in the collider's frame.

:func:`resting_on_features` gives the points of faces resting on features as resting contacts
for the next solve, which then does not pull the faces back onto them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..collision.crossing import box_pairs, element_boxes, segment_segment, triangle_point
from ..collision.kept import KeptPairs, KeptTests
from ..forces.springs import scatter_add
from ..transforms import column_max, column_min, dot_rows, norm_rows, row_any, take
from .contacts import Contacts
from .pair_solve import PointPairs, respond, separate, shares
from .path import CONTACT_DISTANCE, SKIN, ColliderPath, Features

# [m] kept between a collider's features and a mesh's faces, beyond its thickness: less than
# the SKIN a colliding point is placed at, so on a flat face the vertices' own contacts and these
# never push against each other
FACE_GAP = 0.5 * SKIN
ROUNDS = 8  # detections per sub-step: a moved face may come near another part of a feature
DRIFT = 0.25  # kept candidate pairs' margin: this fraction of the mesh's mean edge length
# a point whose pairs' weighted mean normal is shorter than this share of their weights is
# wedged among them (:func:`_per_point`)
WEDGED = 0.8


@dataclass(frozen=True)
class FaceSet:
    """The faces and edges of a system's points.

    Attributes:
        triangles: (m, 3) point indices.
        edges: (q, 2) every edge: the triangles' sides, then the edges on no triangle.
        loose: (r, 2) the edges on no triangle (a wire, a rope): round features meet them
            too (a triangle's sides meet them through the triangle).
    """

    triangles: np.ndarray
    edges: np.ndarray
    loose: np.ndarray

    @classmethod
    def of(cls, triangles: np.ndarray, edges: np.ndarray) -> FaceSet:
        """From triangles (m, 3) and mesh edges (q, 2) (some of them the triangles' sides)."""
        triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
        edges = np.unique(np.sort(np.asarray(edges, np.int64).reshape(-1, 2), axis=1), axis=0)
        sides = np.unique(np.sort(np.stack([triangles, np.roll(triangles, -1, axis=1)], -1)
                                  .reshape(-1, 2), axis=1), axis=0)
        key = np.int64(max(int(edges.max(initial=0)), int(sides.max(initial=0))) + 1)
        loose = edges[~np.isin(edges[:, 0] * key + edges[:, 1], sides[:, 0] * key + sides[:, 1])]
        return cls(triangles, np.concatenate([sides, loose]), loose)

    def __bool__(self) -> bool:
        return bool(len(self.triangles) or len(self.edges))

    def margin(self, x: np.ndarray) -> float:
        """[m] the margin candidate pairs are kept with (:class:`~..collision.crossing.KeptPairs`)
        for points x (n, 3): DRIFT times the mean edge length (0 without edges)."""
        e = self.edges
        return DRIFT * float(np.mean(norm_rows(x[e[:, 1]] - x[e[:, 0]]))) if len(e) else 0.0


def keep_off_features(paths: list[ColliderPath], faces: FaceSet, x0: np.ndarray, x1: np.ndarray,
                      v: np.ndarray, inv_mass: np.ndarray, s0: float, s1: float,
                      rest_speed: float, rounds: int = ROUNDS,
                      near: NearPairs | None = None) -> Contacts:
    """Keep the colliders' features off ``faces`` over a sub-step: points x0 (at s0) -> x1 (at
    s1), (n, 3) [m], velocities v (n, 3) [m/s]; x1 and v are changed in place. Points of zero
    inverse mass (pinned) are never moved. Returns the touched points as contacts (one row per
    point and collider, ``collider`` its index in ``paths``). ``rounds``: detections at most
    (an estimate with fewer skips the fail-safe). ``near``: the mesh's candidate pairs kept
    between detections (:class:`NearPairs`)."""
    found = []
    for ci, path in enumerate(paths):
        features = path.features(s0, s1)
        if not len(features):
            continue
        found_pairs, settled = [], True
        for _ in range(rounds):
            through = []
            pairs = _detect(path, features, faces, x0, x1, s0, s1, through=through, near=near)
            if pairs is None:
                break
            past = np.concatenate(through)
            if past.any() and _home(path, pairs.vertex[past].ravel(), x0, x1, v, inv_mass, s0,
                                    s1):
                continue  # (and detect again: the points back home may uncover others)
            found_pairs.append(pairs)
            if not _separate(path, pairs, x1, inv_mass, s1):
                break
        else:
            settled = False
        if found_pairs:
            found.append(_respond(path, PointPairs.joined(found_pairs), v, inv_mass, s1,
                                  rest_speed, ci))
        if not settled and rounds == ROUNDS:
            _fail_safe(path, features, faces, x0, x1, v, inv_mass, s0, s1, near)
    out = Contacts.none()
    for c in found:
        out = out.merged(c)
    return out


def _fail_safe(path: ColliderPath, features: Features, faces: FaceSet, x0, x1, v, inv_mass,
               s0: float, s1: float, near: NearPairs | None = None) -> None:
    """Points of pairs still crossed after the passes (rare: pushes that undo each other
    round after round) go back to where they were at the start in the collider's frame,
    moving with it — a state in which they did not cross it — and again for what that
    uncovers, so nothing ever ends a sub-step through a feature."""
    for _ in range(ROUNDS):
        pairs = _detect(path, features, faces, x0, x1, s0, s1, near=near)
        if pairs is None:
            return
        _, _, rows = shares(pairs, inv_mass)
        if not _home(path, pairs.vertex[rows][pairs.depth[rows] < 0.0].ravel(), x0, x1, v,
                     inv_mass, s0, s1):
            return


def _home(path: ColliderPath, points: np.ndarray, x0, x1, v, inv_mass, s0: float,
          s1: float) -> bool:
    """The moving ones of ``points`` back where they were at s0 in the collider's frame,
    moving with it (x1 and v in place). Returns whether any moved."""
    stuck = np.unique(points)
    stuck = stuck[inv_mass[stuck] > 0.0]
    if not len(stuck):
        return False
    home = path.to_local(x0[stuck], s0)
    x1[stuck] = path.to_world(home, np.ones_like(home), s1)[0]
    v[stuck] = path.surface_velocity(home, s1)
    return True


def resting_on_features(paths: list[ColliderPath], faces: FaceSet, x: np.ndarray,
                        v: np.ndarray, inv_mass: np.ndarray, s: float, rest_speed: float,
                        skip: frozenset = frozenset(), near: NearPairs | None = None) -> Contacts:
    """The points of faces and edges resting on the colliders' features at s (x (n, 3) [m],
    v (n, 3) [m/s]): pairs nearer than the gap plus CONTACT_DISTANCE whose nearest point does
    not leave faster than ``rest_speed``, as resting contacts of their points (the normal
    their pairs' weighted mean). A solve that holds them there does not pull the faces back
    onto the feature, which the separation after it would then have to undo. Colliders named
    in ``skip`` give none. ``near``: as for :func:`keep_off_features`."""
    found = Contacts.none()
    for ci, path in enumerate(paths):
        features = path.features(s, s)
        if not len(features) or path.frame.name in skip:
            continue
        pairs = _detect(path, features, faces, x, x, s, s, CONTACT_DISTANCE, near=near)
        if pairs is None:
            continue
        share, _, rows = shares(pairs, inv_mass)
        pairs = pairs.take(rows)
        anchor, n = path.to_world(pairs.anchor, pairs.normal, s)
        surface = path.surface_velocity(pairs.anchor, s)
        rel = np.einsum("ck,ckj->cj", pairs.weight, v[pairs.vertex]) - surface
        rest = dot_rows(rel, n) < rest_speed
        if rest.any():
            world = pairs._replace(normal=n, anchor=anchor).take(rest)
            reach = CONTACT_DISTANCE * float(path.per_metre.mean())  # (local, as the pairs)
            found = found.merged(_per_point(world, share[rows][rest], surface[rest], len(x),
                                            path.frame, ci, x, reach))
    return found


def _detect(path: ColliderPath, f: Features, faces: FaceSet, x0, x1, s0: float,
            s1: float, reach: float = 0.0, through: list | None = None,
            near: NearPairs | None = None) -> PointPairs | None:
    """Pairs apart by less than the gap (plus ``reach`` [m]) or crossed, in local units.
    ``through``: given a list, it receives per pair whether a round feature's centre ended
    on the far side of a face (the face went through the whole sphere, not into it: pushing
    it back out the near side would move its points further than the sphere is wide).
    ``near``: the mesh's candidate pairs, kept between detections (the same result)."""
    l0, l1 = path.to_local(x0, s0), path.to_local(x1, s1)
    scale = float(path.per_metre.mean())
    gap = (path.offset + FACE_GAP) * scale
    within = gap + reach * scale
    if not _within_reach(f, l0, l1, within):
        return None
    vertex, weight, normal, anchor, depth = [], [], [], [], []

    def keep(apart, ids, w, sep_normal, point, past=None):
        hit = apart < within
        if through is not None:
            through.append(past[hit] if past is not None else np.zeros(int(hit.sum()), bool))
        vertex.append(ids[hit])
        weight.append(w[hit])
        normal.append(sep_normal[hit])
        anchor.append(point[hit])
        depth.append(apart[hit])

    # the box of each face and edge over the sub-step (from its points' boxes), and of each
    # feature grown by its radius and the reach: (faces, corners and spheres), (edges,
    # creases), (loose edges, spheres)
    low, high = np.minimum(l0, l1), np.maximum(l0, l1)
    grow = (f.radius + within)[:, None]
    boxes = [(*element_boxes(low, high, faces.triangles),
              np.minimum(f.points0, f.points1) - grow, np.maximum(f.points0, f.points1) + grow)]
    ends = ((f.segments0, f.segments1, np.zeros(len(f.segments0)), faces.edges),
            (np.repeat(f.points0[:, None], 2, 1), np.repeat(f.points1[:, None], 2, 1), f.radius,
             faces.loose))
    for ends0, ends1, radius, edges in ends:
        grow = (radius + within)[:, None]
        boxes.append((*element_boxes(low, high, edges),
                      np.minimum(np.minimum(ends0[:, 0], ends0[:, 1]),
                                 np.minimum(ends1[:, 0], ends1[:, 1])) - grow,
                      np.maximum(np.maximum(ends0[:, 0], ends0[:, 1]),
                                 np.maximum(ends1[:, 0], ends1[:, 1])) + grow))
    found = (near.pairs(path, faces, x0, boxes) if near is not None else
             [box_pairs(*b) for b in boxes])

    tests = near.tests(path) if near is not None else None
    moved = tests.begin((l0, l1), (f.points0, f.points1, f.radius),
                        (f.segments0, f.segments1)) if tests is not None else None

    def separations(kind, i, j, count, ids, own, test):
        """``test(rows)`` of pairs (i, j) (elements ``ids`` of the mesh, features of group
        ``own``), through the kept tests where there are."""
        if tests is None:
            return test(np.arange(len(i)))
        stale = row_any(moved[0][ids].reshape(len(i), -1)) | moved[own][j]
        return tests.separations(kind, i * count + j, stale, test)

    i, j = found[0]
    if len(i):
        tri = faces.triangles[i]
        sep = separations("faces", i, j, len(f.points0), tri, 1, lambda r: triangle_point(
            take(l0, tri[r]), take(l1, tri[r]), take(f.points0, j[r]), take(f.points1, j[r])))
        r = f.radius[j]
        point = f.points1[j] + r[:, None] * sep.normal
        keep(sep.gap - r, tri, sep.weight, sep.normal, point, (sep.gap < 0.0) & (r > 0.0))
    for (ends0, ends1, radius, edges), (i, j), kind, own in zip(ends, found[1:],
                                                               ("edges", "loose"), (2, 1)):
        if not len(i):
            continue
        a, b = edges[i, 0], edges[i, 1]
        sep = separations(kind, i, j, len(ends0), edges[i], own,
                          _segment_test(l0, l1, a, b, ends0[j], ends1[j]))
        r = radius[j]
        point = np.einsum("ck,ckj->cj", sep.other, ends1[j]) + r[:, None] * sep.normal
        ids = np.stack([a, b, a], axis=1)
        w = np.concatenate([sep.weight, np.zeros((len(i), 1))], axis=1)
        keep(sep.gap - r, ids, w, sep.normal, point)
    if not vertex or not sum(len(a) for a in vertex):
        return None
    return PointPairs(np.concatenate(vertex), np.concatenate(weight), np.concatenate(normal),
                      np.concatenate(anchor), np.concatenate(depth), gap)


def _segment_test(l0, l1, a, b, ends0, ends1):
    """The continuous test of mesh edges a-b (points l0 -> l1) against the segments ends0 ->
    ends1 (c, 2, 3), for the pairs ``rows`` (points gathered with ``take``: 3 x faster than
    fancy indexing of rows)."""
    return lambda r: segment_segment(take(l0, a[r]), take(l0, b[r]), ends0[r, 0], ends0[r, 1],
                                     take(l1, a[r]), take(l1, b[r]), ends1[r, 0], ends1[r, 1])


class NearPairs:
    """The candidate pairs of the colliders' features and a mesh's faces and edges, kept between
    detections (:class:`~..collision.crossing.KeptPairs`, per collider and kind of pair). A
    sub-step detects many times — resting faces, each landing round's estimate, each
    separating round — with the faces and features barely moved between them, as between the
    sub-steps of a mesh at rest; finding the pairs of 12,000 edge boxes and 1,500 crease boxes
    is most of a detection. The result is exactly a fresh search's. One per mesh and run."""

    def __init__(self):
        self._kept: dict[tuple[str, int], KeptPairs] = {}
        self._tests: dict[str, KeptTests] = {}  # per collider: the last detection's tests
        self._margin: float | None = None  # [m] (:meth:`FaceSet.margin`)

    def tests(self, path: ColliderPath) -> KeptTests:
        """The continuous tests kept between detections on ``path`` (the same results as
        testing every pair)."""
        return self._tests.setdefault(path.frame.name, KeptTests())

    def pairs(self, path: ColliderPath, faces: FaceSet, x0: np.ndarray, boxes: list) -> list:
        """:func:`box_pairs` of each of ``boxes`` (lo_a, hi_a, lo_b, hi_b) of a detection on
        ``path`` (in its local units; the mesh's points x0 (n, 3) [m] at the start)."""
        if self._margin is None:
            self._margin = faces.margin(x0)
        margin = self._margin * float(path.per_metre.mean())
        return [self._kept.setdefault((path.frame.name, k), KeptPairs()).pairs(margin, *b)
                for k, b in enumerate(boxes)]


def _within_reach(f: Features, l0: np.ndarray, l1: np.ndarray, near: float) -> bool:
    """Whether any feature's box (grown by its radius and ``near``) meets the box of the whole
    mesh over the sub-step, l0 -> l1 (n, 3) local: most of the time none does (a cloth on a
    wide ground plane is far from its corners and edges), and then no face or edge needs a
    box of its own."""
    if not len(l0):
        return False
    lo = np.minimum(column_min(l0), column_min(l1))
    hi = np.maximum(column_max(l0), column_max(l1))
    grow = (f.radius + near)[:, None]
    boxes = [(np.minimum(f.points0, f.points1) - grow, np.maximum(f.points0, f.points1) + grow)]
    if len(f.segments0):
        s0, s1 = f.segments0, f.segments1  # (each segment's ends: element-wise, not reduced)
        boxes.append((np.minimum(np.minimum(s0[:, 0], s0[:, 1]),
                                 np.minimum(s1[:, 0], s1[:, 1])) - near,
                      np.maximum(np.maximum(s0[:, 0], s0[:, 1]),
                                 np.maximum(s1[:, 0], s1[:, 1])) + near))
    return any(bool(np.any(np.all((b_lo <= hi) & (b_hi >= lo), axis=1))) for b_lo, b_hi in boxes)


def _separate(path: ColliderPath, pairs: PointPairs, x1, inv_mass, s1: float) -> bool:
    """Restore the pairs' gaps (x1 in place, moved in the collider's frame). Returns whether
    any was short."""
    l1 = path.to_local(x1, s1)
    moved = separate(pairs, l1, inv_mass)
    if moved is None:
        return False
    x1[moved] = path.to_world(l1[moved], np.ones((len(moved), 3)), s1)[0]
    return True


def _respond(path: ColliderPath, pairs: PointPairs, v, inv_mass, s1: float, rest_speed: float,
             which: int) -> Contacts:
    anchor, n = path.to_world(pairs.anchor, pairs.normal, s1)
    surface = path.surface_velocity(pairs.anchor, s1)
    rows = respond(pairs, v, inv_mass, n, surface, path.frame.friction,
                   path.frame.restitution, rest_speed)
    share = shares(pairs, inv_mass)[0]
    world = pairs._replace(normal=n, anchor=anchor).take(rows)
    return _per_point(world, share[rows], surface[rows], len(v), path.frame, which)


def _per_point(pairs: PointPairs, share: np.ndarray, surface: np.ndarray, count: int, frame,
               which: int, at: np.ndarray | None = None, reach: float | None = None
               ) -> Contacts:
    """Contacts of the points that world-space ``pairs`` move: each with the mean of its
    pairs' normals weighted by its share of them (its first pair's point and surface
    velocity; its own position when ``at`` is given), wedged where that mean is shorter than
    WEDGED times their weight (two equal pairs more than 74 degrees apart: no one normal
    keeps them all, and a point held along the mean slid into the others, was pushed back out
    of them and slid in again every sub-step — a cloth on Suzanne's brow buzzing at 4 cm/s).
    ``reach``: pairs found up to this far beyond the gap (local units, as their depths), whose
    say in the mean fades to nothing over it (as the square of the share of the reach still
    ahead of them): a pair coming into reach or leaving it turns the normal by a little, not
    by its whole weight. (At full weight, six pairs of a cloth edge and the creases that meet
    at one of Suzanne's corners, each 0.97 mm away, came into reach in one sub-step and left
    in the next: the point's normal swung by 43 degrees each sub-step, and it kicked its free
    neighbours at 5-10 mm/s for good.)"""
    rows = np.nonzero(share > 0.0)
    index, first = np.unique(pairs.vertex[rows], return_index=True)
    pair = rows[0][first]
    weight = pairs.weight[rows]
    if reach is not None:
        ahead = np.clip((pairs.gap + reach - pairs.depth[rows[0]]) / reach, 0.0, 1.0)
        weight = weight * ahead * ahead
    summed = np.zeros((count, 3))
    scatter_add(summed, pairs.vertex[rows], weight[:, None] * pairs.normal[rows[0]])
    normal = summed[index]
    length = norm_rows(normal)
    weights = np.bincount(pairs.vertex[rows], weights=weight, minlength=count)[index]
    wedged = length < WEDGED * weights
    # (a mean of normals that nearly cancel: its first pair's)
    meant = length > (0.5 if reach is None else 0.5 * np.minimum(weights, 1.0))
    normal = np.where(meant[:, None], normal / np.maximum(length, 1e-300)[:, None],
                      pairs.normal[pair])
    point = pairs.anchor[pair] if at is None else at[index]
    return Contacts.of(index, point, normal, surface[pair],
                       np.full(len(index), frame.friction), np.full(len(index), frame.restitution),
                       collider=np.full(len(index), which), wedged=wedged)
