"""A spring mesh against itself: cloth folding onto itself, a cloth dropped into a heap. Its
vertices are kept off its triangles and its edges off its edges (pairs that share no vertex),
``distance`` apart, and no pair ever crosses.

Per sub-step, after the step and the colliders (positions x0 -> x1):

1. detect: vertex-triangle and edge-edge pairs whose boxes over the sub-step overlap (the
   library's uniform grid: across the triangles and the points, within the edges; the pairs
   are kept between detections while the boxes move less than a margin,
   :class:`~..collision.crossing.KeptPairs`), then those nearer than the distance at the end
   or that crossed during the step (continuous tests, :mod:`..collision.crossing`: the side
   each came from; a detection after a separating round tests again only the pairs with a
   moved point, :class:`~..collision.kept.KeptTests`, and of those not the ones whose
   last gap, less how far their points moved since, shows them still apart: :class:`_Apart`);
2. separate: each pair's weighted points pushed apart along its normal, in proportion to
   their inverse masses (:mod:`..contact.pair_solve`: Gauss-Seidel over coloured pairs, or
   relaxed Jacobi passes where a heap crowds dozens of pairs on a point), then detect again,
   up to ROUNDS times;
3. respond: the pairs' approach speeds cancelled, Coulomb friction on their sliding — equal
   and opposite on both sides, so the mesh's momentum is unchanged;
4. fail safe: points of pairs still crossed go back to where they started the sub-step (a
   state in which nothing crossed) with their group's mean velocity, as often as that
   uncovers more; if any remain, the whole mesh does;
5. carry: each pair's impulses of step 3, as forces, added to those it carried (:class:`Carried`),
   act in the next sub-step's implicit solve (:meth:`SelfCollision.forces`). Without them the
   solve sees no layer under another: a layer resting on a fold sagged into it every sub-step
   and the springs around the fold pulled it along before the passes lifted it back and
   friction stopped it, so a pile of folds never came to rest (a towel's crept across the floor
   at 6 mm/s, its folds twitching) and the layer on the ground never felt the weight on it.
"""
from __future__ import annotations

from functools import partial
from typing import NamedTuple

import numpy as np

from ..collision.broadphase_grid import TooManyCandidates, UniformGrid
from ..collision.crossing import (MEET, TINY, box_pairs, element_boxes, segment_segment,
                                  triangle_point)
from ..collision.kept import KeptPairs, KeptTests
from ..contact.features import FaceSet
from ..contact.pair_solve import PointPairs, respond, separate, shares, within_cone
from ..errors import SimulationError
from ..forces.springs import scatter_add
from ..helper_process import Helper, HelperError
from ..transforms import norm_rows, row_any, row_max
from .self_collision_helper import helper_mode, start_helper

ROUNDS = 8  # detections per sub-step
GROUNDED_SHARE = 0.01  # of the inverse mass a point touching a collider keeps here
CARRY_KEEP = 0.9  # of a pair's carried force kept into the next sub-step (see Carried)
# Candidate pairs per triangle (vertices) or per edge (edges) beyond which a detection is
# refused: a heap of folds has up to about 15; a mesh whose faces sweep across each other in
# one sub-step (a closed mesh pushed flat out of deep inside a collider: over 300) would take
# minutes per sub-step to test, and its motion is no cloth's. (Elements that share a vertex
# are not candidates: a grid's triangle has 3 such points, its edge about 5 such edges.)
CROWD_LIMIT = 100
SEARCH_LIMIT = 10  # x CROWD_LIMIT: the candidate pairs per element a search may make before
# testing their boxes (a refused search fails the same way, before filling memory)


class Carried(NamedTuple):
    """The contact forces of the pairs found in the last sub-step, carried into the next
    sub-step's solve: per pair (key sorted (m,)), its points, weights and normal, and its
    force per unit weight along the normal (m,) [N] and across it (m, 3) [N], within the
    friction cone. A pair found again adds its new impulses over the sub-step to CARRY_KEEP of
    what it carried (a force the load no longer needs fades; at rest the passes make up the
    rest each sub-step); a pair not found again carries nothing. Each force is equal and
    opposite over its pair's points (the weights sum to zero): the mesh's momentum is kept."""

    key: np.ndarray
    vertex: np.ndarray
    weight: np.ndarray
    normal: np.ndarray
    normal_force: np.ndarray
    friction_force: np.ndarray


class SelfCollision:
    """Keeps one mesh's faces and edges apart.

    Args:
        faces: the mesh's triangles and edges. mass: (n,) [kg] (pinned points: inverse mass 0
        in ``inv_mass``). inv_mass: (n,) [1/kg]. distance: kept between any vertex and
        triangle, edge and edge that share no vertex [m] (> 0). friction: Coulomb mu.
    """

    def __init__(self, faces: FaceSet, mass: np.ndarray, inv_mass: np.ndarray, distance: float,
                 friction: float):
        self.faces = faces
        self.mass = mass
        self.inv_mass = inv_mass
        self.distance = float(distance)
        self.friction = float(friction)
        # the candidate pairs, kept between detections (the same pairs as a fresh search)
        limit = SEARCH_LIMIT * CROWD_LIMIT
        self._faces_points = KeptPairs(partial(box_pairs,
                                               max_candidates=limit * len(faces.triangles)))
        per_edges = limit * len(faces.edges)
        self._edges = KeptPairs(partial(_pairs_within, max_candidates=per_edges), within=True,
                                across=partial(box_pairs, max_candidates=per_edges))
        self._leave_out_neighbours()
        self._tests = KeptTests()  # and their tests, for the pairs whose points did not move
        self._margin: float | None = None
        self._last_end: np.ndarray | None = None  # x1 of the last detection (see _Apart)
        self.carried: Carried | None = None
        self._fresh = True  # the next update starts a sub-step's carried forces
        self._helper_mode = helper_mode()
        self._helper: Helper | None = None  # finding the point pairs (.self_collision_helper)
        self._helper_tried = False  # (one start per bake: a helper that failed is not restarted)

    def _leave_out_neighbours(self) -> None:
        """The candidate pairs leave out the pairs that share a vertex (a triangle and its
        corners, edges meeting at a point): always near, never tested, and most of the
        candidates."""
        self._faces_points.exclude = partial(_corner_of, self.faces.triangles)
        self._edges.exclude = partial(_edges_meet, self.faces.edges)

    def __getstate__(self):
        # (its kept tests are not kept either; nor its helper, which a resumed bake starts
        # as the environment it resumes in says)
        return {**self.__dict__, "_last_end": None, "_helper": None, "_helper_tried": False,
                "_helper_mode": None}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update({"_last_end": None, **state, "_helper": None,
                              "_helper_tried": False, "_helper_mode": None})
        self._leave_out_neighbours()  # (a checkpoint written before they were left out)

    def close(self) -> None:
        """End the helper process, if any (a later detection does its work here)."""
        if self._helper is not None:
            self._helper.close()
            self._helper = None
        self._helper_tried = True

    def _helper_ready(self) -> Helper | None:
        """The helper process (:mod:`.self_collision_helper`), started at the first detection
        where it pays, once it is ready (until then, and if it cannot start or fails, the point
        pairs are found here: the same pairs, its kept candidates and tests being exact)."""
        if self._helper is None:
            if self._helper_mode is None:  # (resumed: as the environment says now)
                self._helper_mode = helper_mode()
            if self._helper_tried:
                return None
            self._helper_tried = True
            self._helper = start_helper(self)
            if self._helper is None:
                return None
        try:
            return self._helper if self._helper.ready else None
        except HelperError:
            self._helper = None
            return None

    def begin_substep(self) -> None:
        """The next :meth:`keep_apart` begins a sub-step: the carried forces it finds replace
        the last sub-step's (later calls in the same sub-step add to them)."""
        self._fresh = True

    def forces(self, n: int) -> np.ndarray | None:
        """(n, 3) [N] the carried contact forces on the points (equal and opposite over each
        pair: they sum to zero), or None."""
        c = self.carried
        if c is None or not len(c.key):
            return None
        f = np.zeros((n, 3))
        per = c.normal_force[:, None] * c.normal + c.friction_force
        scatter_add(f, c.vertex, c.weight[:, :, None] * per[:, None, :])
        return f

    def keep_apart(self, x0: np.ndarray, x1: np.ndarray, v: np.ndarray, rest_speed: float,
                   grounded: np.ndarray | None = None, h: float | None = None,
                   lifted: np.ndarray | None = None) -> int:
        """Sub-step x0 -> x1 (n, 3) [m], velocities v (n, 3) [m/s]; x1 and v in place.
        ``grounded``: (k,) points touching a collider this sub-step, which the mesh's own
        pushes move GROUNDED_SHARE as far as the others (a layer on the ground is hardly
        pushed into it: the one on top moves; two layers meeting on it still part). Every
        pair sees the same inverse masses, which keeps the passes convergent. ``lifted``:
        (l,) points among them that a collider lifted back after an earlier pass of this
        sub-step; the separating passes move them GROUNDED_SHARE as far again (the velocity
        response and the carried forces do not: its impulses stay those of the masses the
        solve knows). Where a layer has crumpled flat on the ground, a vertex lying on a
        triangle of its own layer, both grounded, was pushed half into the ground and lifted
        back every round, and was left at a seventh of the distance. Returns the pairs
        handled."""
        inv_mass = self.inv_mass
        if grounded is not None and len(grounded):
            inv_mass = inv_mass.copy()
            inv_mass[grounded] *= GROUNDED_SHARE
        moves = inv_mass
        if lifted is not None and len(lifted):
            moves = inv_mass.copy()
            moves[lifted] *= GROUNDED_SHARE
        found, keys, settled = [], [], True
        for _ in range(ROUNDS):
            pairs = self._detect(x0, x1, keys)
            if pairs is None:
                break
            found.append(pairs)
            if separate(pairs, x1, moves, coloured=None) is None:
                break
        else:
            settled = False
        if not found:
            if h is not None and self._fresh:
                self.carried, self._fresh = None, False
            return 0
        # each pair once, as the latest detection found it (a pair found again after a
        # separating round was the same constraint twice, which halved its relaxed passes' steps)
        keys = np.concatenate(keys)
        backwards = np.unique(keys[::-1], return_index=True)[1]
        latest = np.sort(len(keys) - 1 - backwards)
        pairs, keys = PointPairs.joined(found).take(latest), keys[latest]
        impulses = []
        respond(pairs, v, inv_mass, pairs.normal, np.zeros_like(pairs.normal), self.friction,
                0.0, rest_speed, coloured=None, impulses=impulses)
        if h is not None and impulses:
            self._carry(pairs, keys, *impulses, h)
        if not settled:
            self.fail_safe(x0, x1, v)
        return len(shares(pairs, inv_mass)[2])

    def _carry(self, pairs: PointPairs, keys: np.ndarray, pushed: np.ndarray,
               held: np.ndarray, h: float) -> None:
        """This sub-step's impulses of each pair (``keys``: one row each), as forces, added
        to what its pair carried (CARRY_KEEP of it at a sub-step's start), the friction within
        the cone."""
        order = np.argsort(keys)
        unique, normal = keys[order], pairs.normal[order]
        fn, ft = pushed[order] / h, held[order] / h
        base, keep = self.carried, CARRY_KEEP if self._fresh else 1.0
        self._fresh = False
        if base is not None and len(base.key):
            at = np.minimum(np.searchsorted(base.key, unique), len(base.key) - 1)
            hit = base.key[at] == unique
            fn = fn + keep * np.where(hit, base.normal_force[at], 0.0)
            old = np.where(hit[:, None], base.friction_force[at], 0.0)
            old -= np.einsum("ij,ij->i", old, normal)[:, None] * normal
            ft = ft + keep * old
        fn = np.maximum(fn, 0.0)
        within_cone(ft, self.friction * fn)
        self.carried = Carried(unique, pairs.vertex[order], pairs.weight[order], normal, fn, ft)

    def fail_safe(self, x0, x1, v) -> None:
        """Step 4 of the module docstring: the points of pairs that crossed between x0 (a
        state in which nothing crossed) and x1 go back to x0 (x1 and v in place)."""
        for _ in range(ROUNDS):
            stuck = self._crossed(x0, x1)
            if not len(stuck):
                return
            self._restart(stuck, x0, x1, v)
        if len(self._crossed(x0, x1)):
            self._restart(np.nonzero(self.inv_mass > 0.0)[0], x0, x1, v)

    def _crossed(self, x0, x1) -> np.ndarray:
        """The moving points of pairs that crossed."""
        pairs = self._detect(x0, x1)
        if pairs is None:
            return np.zeros(0, np.int64)
        stuck = pairs.vertex[(pairs.depth < 0.0)[:, None] & (pairs.weight != 0.0)]
        return np.unique(stuck[self.inv_mass[stuck] > 0.0])

    def _restart(self, points: np.ndarray, x0, x1, v) -> None:
        """``points`` back where they started, moving together (momentum kept)."""
        m = self.mass[points][:, None]
        x1[points] = x0[points]
        v[points] = (m * v[points]).sum(axis=0) / m.sum()

    def _detect(self, x0: np.ndarray, x1: np.ndarray, keys: list | None = None
                ) -> PointPairs | None:
        """Pairs nearer than the distance at the end, or crossed; ``keys``: each pair's key
        appended (triangle and point, or the two edges). The point pairs are found by the
        helper process where there is one (:meth:`_helper_ready`) while the edge pairs are
        found here: the same pairs either way, and the same error where a search refuses a
        crowded sub-step (the points' first)."""
        if self._margin is None:
            self._margin = self.faces.margin(x0)
        helper = self._helper_ready()
        if helper is not None:
            try:
                helper.ask((x0, x1, self._margin))
            except HelperError:
                helper = self._helper = None
        frame = self._prepare(x0, x1)
        if helper is None:
            parts = [self._point_pairs(x0, x1, *frame), self._edge_pairs(x0, x1, *frame)]
        else:
            failure = None
            try:
                edges = self._edge_pairs(x0, x1, *frame)
            except Exception as exc:  # (raised after the points' error, as without a helper)
                edges, failure = None, exc
            try:
                answer = helper.answer()
            except HelperError:
                self._helper = None
                answer = "pairs", self._point_pairs(x0, x1, *frame)
            if answer[0] == "error":
                raise SimulationError(answer[1])
            if failure is not None:
                raise failure
            parts = [answer[1], edges]
        parts = [p for p in parts if p is not None]
        if not parts:
            return None
        vertex, weight, normal, depth, key = (np.concatenate(a) for a in zip(*parts))
        if not len(vertex):
            return None
        if keys is not None:
            keys.append(key)
        return PointPairs(vertex, weight, normal, np.zeros_like(normal), depth, self.distance)

    def _prepare(self, x0: np.ndarray, x1: np.ndarray) -> tuple:
        """What both kinds of pair are found from: the points' boxes over the sub-step (lo, hi
        (n, 3), grown by half the distance), the points moved since the last detection and
        the bound of :class:`_Apart`."""
        d = self.distance
        # the boxes sweep the motion relative to the mesh's mean motion: the pairs and their
        # gaps are the same in any frame moving with it, and a mesh falling or thrown as a
        # whole no longer sweeps each element's box across its neighbours' (a sheet falling
        # on edge at 40 m/s: every triangle's box met 25 rows of others); and they are given
        # about the mesh's centre at the start, so a mesh moving as a whole keeps its boxes
        # within those its candidate pairs were found for (KeptPairs) from sub-step to sub-step
        drift = (x1 - x0).mean(axis=0)
        centre = x0.mean(axis=0)
        x0_moving, x1_moving = x0 - centre, x1 - (drift + centre)
        lo = np.minimum(x0_moving, x1_moving) - 0.5 * d
        hi = np.maximum(x0_moving, x1_moving) + 0.5 * d
        moved, = self._tests.begin((x0, x1))
        far = _Apart(x0, x1, self._last_end, d)
        self._last_end = x1.copy()
        return lo, hi, moved, far

    def _point_pairs(self, x0, x1, lo, hi, moved, far) -> tuple | None:
        """The points near triangles: (vertex (c, 4), weight (c, 4), normal (c, 3), depth (c,),
        key (c,)), or None."""
        tris = self.faces.triangles
        if not len(tris):
            return None
        i, j = self._search(self._faces_points, "triangle", x0, x1,
                            *element_boxes(lo, hi, tris), lo, hi)
        if not len(i):
            return None
        sep = self._tests.separations(
            "faces", i * len(x0) + j, row_any(moved[tris[i]]) | moved[j],
            lambda r: triangle_point(x0[tris[i[r]]], x1[tris[i[r]]], x0[j[r]], x1[j[r]]),
            lambda r, gap: far(gap, tris[i[r]], j[r, None]))
        near = sep.gap < self.distance
        return (np.concatenate([tris[i], j[:, None]], axis=1)[near],
                np.concatenate([sep.weight, -np.ones((len(i), 1))], axis=1)[near],
                sep.normal[near], sep.gap[near], (i * len(x0) + j)[near])

    def _edge_pairs(self, x0, x1, lo, hi, moved, far) -> tuple | None:
        """The edges near edges, as :meth:`_point_pairs` gives the points (keys after every
        point pair's)."""
        tris, edges = self.faces.triangles, self.faces.edges
        if not len(edges):
            return None
        i, j = self._search(self._edges, "edge", x0, x1, *element_boxes(lo, hi, edges))
        a, b = edges[i], edges[j]
        if not len(a):
            return None
        sep = self._tests.separations(
            "edges", i * len(edges) + j,
            row_any(moved[a]) | row_any(moved[b]),
            lambda r: segment_segment(x0[a[r, 0]], x0[a[r, 1]], x0[b[r, 0]], x0[b[r, 1]],
                                      x1[a[r, 0]], x1[a[r, 1]], x1[b[r, 0]], x1[b[r, 1]]),
            lambda r, gap: far(gap, a[r], b[r]))
        near = sep.gap < self.distance
        return (np.concatenate([a, b], axis=1)[near],
                np.concatenate([sep.weight, -sep.other], axis=1)[near], sep.normal[near],
                sep.gap[near], len(tris) * len(x0) + (i * len(edges) + j)[near])

    def _search(self, kept: KeptPairs, what: str, x0: np.ndarray, x1: np.ndarray, lo, hi,
                *other) -> tuple[np.ndarray, np.ndarray]:
        """The candidate pairs of the ``what`` boxes ``lo``, ``hi`` (against ``other``'s, or
        among themselves), refused when crowded (:meth:`_not_crowded`)."""
        try:
            i, j = kept.pairs(self._margin, lo, hi, *other)
        except TooManyCandidates as exc:
            self._not_crowded(exc.candidates, len(lo), what, x0, x1)
        self._not_crowded(len(i), len(lo), what, x0, x1)
        return i, j

    def _not_crowded(self, pairs: int, elements: int, what: str, x0: np.ndarray,
                     x1: np.ndarray) -> None:
        """A SimulationError (the caller names the mesh and frame) when the sub-step's boxes
        put more than CROWD_LIMIT candidate pairs on each of the ``elements``."""
        if pairs <= CROWD_LIMIT * elements:
            return
        move = float(np.sqrt(np.einsum("ij,ij->i", x1 - x0, x1 - x0).max()))
        raise SimulationError(
            f"self-collision found {pairs:,} candidate pairs for its {elements:,} {what}s in "
            f"one sub-step (more than {CROWD_LIMIT} each): its vertices moved up to "
            f"{move:.3g} m in the sub-step against a self-collision distance of "
            f"{self.distance:g} m, so its faces swept across each other (as when a collider "
            "pushes a mesh out from deep inside it) — start the mesh outside the colliders, "
            "add substeps, or turn Self Collision off")


class _Apart:
    """Which pairs the last detection tested need no test now: a pair's distance changes by
    at most its two elements' largest point moves (a point's distance to a triangle, a
    segment's to a segment, is 1-Lipschitz in each one's points), and its kept gap is at most
    its distance then (the distance along the normal, negative when crossed, or a bound kept
    by this rule), so the last gap less what its points moved since (``last_end`` to ``x1``)
    bounds the distance now from below; a pair whose bound
    exceeds the distance and its points' motion over the sub-step (``x0`` to ``x1``; with
    meeting's tolerance, as :func:`~..collision.crossing.triangle_point` skips its crossing
    test) is neither near at the end nor can have met during it. Called per kind of pair with
    the last gaps (r,) and each pair's points as two groups (r, k) and (r, l): (far (r,), the
    bound (r,))."""

    def __init__(self, x0: np.ndarray, x1: np.ndarray, last_end: np.ndarray | None,
                 distance: float):
        self.ok = last_end is not None and last_end.shape == x1.shape
        if self.ok:
            self.shift = norm_rows(x1 - last_end)
            self.motion = norm_rows(x1 - x0)
            # any element is smaller, at the start and at the end
            size = float(np.linalg.norm(np.maximum(np.ptp(x0, axis=0), np.ptp(x1, axis=0))))
            self.floor = 2.0 * MEET * size + 2.0 * TINY
        self.distance = distance

    def __call__(self, gap: np.ndarray, first: np.ndarray, second: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        if not self.ok:
            return np.zeros(len(gap), bool), gap
        bound = gap - (row_max(self.shift[first]) + row_max(self.shift[second]))
        motion = row_max(self.motion[first]) + row_max(self.motion[second])
        # (with meeting's tolerance on both: two nearly parallel segments' gap can exceed
        # their distance by about MEET of their length)
        far = (bound > self.distance + self.floor) & (bound > (1.0 + 1e-6) * motion + self.floor)
        return far, bound


def _pairs_within(lo: np.ndarray, hi: np.ndarray, max_candidates: int | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Every overlapping pair (i < j) of the boxes (k, 3), sorted by i then j: the library's
    uniform grid over one set (each pair found once; a grid across two copies of the set
    finds each twice and every box with itself, and took 4 x as long), which gives them so."""
    i, j = np.ascontiguousarray(UniformGrid(max_candidates=max_candidates).pairs(lo, hi).T)
    return i, j


def _corner_of(tris: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """(c,) whether point j is a corner of triangle i."""
    t = tris[i]
    return (t[:, 0] == j) | (t[:, 1] == j) | (t[:, 2] == j)


def _edges_meet(edges: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """(c,) whether edges i and j share a point."""
    a, b = edges[i], edges[j]
    return (a[:, 0] == b[:, 0]) | (a[:, 0] == b[:, 1]) | (a[:, 1] == b[:, 0]) | \
        (a[:, 1] == b[:, 1])
