"""Gravitational attraction among point masses: the exact pairwise sum, and Barnes and Hut's tree
code that approximates far groups of masses by their total mass at their centre of mass.

Both use Plummer softening: the acceleration of i is

    a_i = G sum_j m_j (x_j - x_i) / (|x_j - x_i|^2 + eps^2)^(3/2),

finite at any distance (two stars passing through each other do not fling apart).

The tree is a linear octree: points sorted along the Morton (Z-order) curve of their cells, a
node at level L being a run of points sharing the code's first 3 L bits; a node of at most
:data:`LEAF_SIZE` points is a leaf (a *bucket*; at :data:`MAX_LEVEL` a leaf holds however many
points share its cell). Traversal is vectorised over buckets: a frontier of (bucket, node)
pairs, level by level; a node is far from a bucket when its cell's side s and the distance d
from its centre of mass to the bucket's bounding box satisfy s < theta d, and then every point
of the bucket takes the node's monopole; a leaf that is not far gives its points one by one;
other nodes open into their children. Each bucket's sources (far monopoles and near points) are
then met by all its points at once (:func:`_pull_groups`). theta = 0 is the exact sum.
Error against theta is measured in the tests and printed by the benchmark.
"""
from __future__ import annotations

import numpy as np

from ..collision.broadphase_octree import _morton

# points per bucket: its points share one interaction list (:func:`_pull_groups`); 32 took
# 0.7-0.9 x the time of 16 from 10,000 to 1,000,000 bodies (fewer buckets to traverse), its field
# a little closer to the exact sum (bigger boxes open more nodes); 64 was slower again
LEAF_SIZE = 32
MAX_LEVEL = 21  # 21 bits per axis in a 63-bit Morton code
EXACT_BELOW = 1024  # fewer points: the exact sum is cheaper than a tree
BATCH = 2_000_000  # point pairs of the exact sum evaluated at once
BLOCK = 1 << 17  # (point, source) pairs of one dense block, padding included (cache-sized)
PAD_AWAY = 1e30  # [m] where the empty source that pads the blocks sits (it has no mass)
PAD_TO = 32  # a group's sources are padded to a multiple of this
# buckets traversed together: their frontier and lists stay small (8,192 took 1.3 x as long
# at 100,000 bodies: its frontier outgrew FRONTIER_LIMIT, and what it had traversed was thrown
# away; 512-2,048 all ran within a few per cent)
GROUP_CHUNK = 1024
FRONTIER_LIMIT = 4_000_000  # (group, node) pairs a traversal may hold at once (about 100 MB);
# more, and fewer groups are traversed together
MAX_INTERACTIONS = 200_000_000  # point-source interactions of one evaluation that are always
PER_BODY = 10_000  # allowed, or this many per point if more (theta 0.5 takes about 2,700 at a
# million points, 55 s); beyond, an evaluation is refused: a tiny opening angle over many
# points is nearly the exact sum (240,000 points: 6e10 interactions, days a step)


def interaction_limit(points: int) -> int:
    """The most point-source interactions one evaluation over ``points`` may take."""
    return max(MAX_INTERACTIONS, PER_BODY * int(points))


class TooManyInteractions(ValueError):
    """An evaluation would take more than :func:`interaction_limit` point-source interactions
    (an opening angle too small for the point count); ``interactions``: its estimate."""

    def __init__(self, interactions: int):
        super().__init__(f"about {interactions:,} interactions")
        self.interactions = int(interactions)


class _FrontierFull(TooManyInteractions):
    """A traversal's frontier outgrew FRONTIER_LIMIT (traverse fewer groups at once)."""


def exact_accelerations(x: np.ndarray, m: np.ndarray, G: float, eps: float) -> np.ndarray:
    """a (n, 3) [m/s^2] by the exact pairwise sum, each pair once, equal and opposite (total
    momentum and angular momentum change by rounding only)."""
    n = len(x)
    a = np.zeros((n, 3))
    if n < 2:
        return a
    for ii, jj in _pair_blocks(n):
        d = x[jj] - x[ii]
        r2 = np.einsum("ij,ij->i", d, d) + eps * eps
        with np.errstate(divide="ignore"):  # two points at one place pull along no axis
            inv = np.where(r2 > 0.0, 1.0 / (r2 * np.sqrt(r2)), 0.0)
        f = G * d * inv[:, None]  # per unit mass of both
        for k in range(3):
            a[:, k] += np.bincount(ii, f[:, k] * m[jj], minlength=n)
            a[:, k] -= np.bincount(jj, f[:, k] * m[ii], minlength=n)
    return a


def _pair_blocks(n: int):
    """Every pair i < j of n points, a block of rows at a time (about BATCH pairs each)."""
    row = 0
    while row < n - 1:
        # rows row..stop-1 hold (n - 1 - r) pairs each
        stop = row + 1
        total = n - 1 - row
        while stop < n - 1 and total + (n - 1 - stop) <= BATCH:
            total += n - 1 - stop
            stop += 1
        rows = np.arange(row, stop)
        width = n - 1 - rows
        ii = np.repeat(rows, width)
        jj = _ranges(rows + 1, width)
        yield ii, jj
        row = stop


class Octree:
    """The linear octree of points ``x`` (n, 3) with masses ``m`` (n,) (see the module
    docstring). Node arrays, all levels together: ``node_start``/``node_count`` (their run of the
    sorted points), ``node_level``, ``node_mass``, ``node_com`` (n_nodes, 3), ``node_size``
    (cell side [m]), ``node_child``/``node_children`` (first child index, count; 0 for leaves).
    """

    def __init__(self, x: np.ndarray, m: np.ndarray, leaf_size: int = LEAF_SIZE):
        lo, hi = x.min(axis=0), x.max(axis=0)
        side = float((hi - lo).max()) * (1.0 + 1e-9) or 1.0
        cell = np.floor((x - lo) / side * (1 << MAX_LEVEL)).astype(np.int64)
        cell = np.clip(cell, 0, (1 << MAX_LEVEL) - 1)
        code = _morton(cell.T)
        self.order = np.argsort(code, kind="stable")
        code = code[self.order]
        xs, ms = x[self.order], m[self.order]
        self.x, self.m = xs, ms
        cum_m = np.concatenate([[0.0], np.cumsum(ms)])
        cum_mx = np.concatenate([np.zeros((1, 3)), np.cumsum(ms[:, None] * xs, axis=0)])
        starts, counts, levels, parents = [np.zeros(1, np.int64)], [np.array([len(x)])], \
            [np.zeros(1, np.int64)], [np.full(1, -1)]
        open_ = np.array([len(x) > leaf_size])
        first = 0  # index of the current level's first node
        level = 0
        while open_.any() and level < MAX_LEVEL:
            level += 1
            s0, c0 = starts[-1][open_], counts[-1][open_]
            parent_index = first + np.flatnonzero(open_)
            # the children: runs of equal level-L keys inside each open node
            idx = np.repeat(s0, c0) + (np.arange(int(c0.sum()))
                                       - np.repeat(np.cumsum(c0) - c0, c0))
            key = code[idx] >> (3 * (MAX_LEVEL - level))
            owner = np.repeat(np.arange(len(s0)), c0)
            change = np.concatenate([[True], (np.diff(key) != 0) | (np.diff(owner) != 0)])
            run_first = np.flatnonzero(change)
            run_start = idx[run_first]
            run_count = np.diff(np.concatenate([run_first, [len(idx)]]))
            first += len(starts[-1])
            starts.append(run_start)
            counts.append(run_count)
            levels.append(np.full(len(run_start), level))
            parents.append(parent_index[owner[run_first]])
            open_ = run_count > leaf_size
        self.node_start = np.concatenate(starts)
        self.node_count = np.concatenate(counts)
        self.node_level = np.concatenate(levels)
        parent = np.concatenate(parents)
        total = len(self.node_start)
        self.node_children = np.bincount(parent[1:], minlength=total)
        # children of a node are consecutive (the levels are built in the parents' order)
        self.node_child = np.zeros(total, np.int64)
        has = self.node_children > 0
        first_child = np.full(total, total, np.int64)
        np.minimum.at(first_child, parent[1:], np.arange(1, total))
        self.node_child[has] = first_child[has]
        end = self.node_start + self.node_count
        self.node_mass = cum_m[end] - cum_m[self.node_start]
        self.node_com = (cum_mx[end] - cum_mx[self.node_start]) / np.where(
            self.node_mass > 0.0, self.node_mass, 1.0)[:, None]
        self.node_size = side / (1 << self.node_level).astype(np.float64)
        self.leaves = np.flatnonzero(~has)
        # the targets: the leaves (buckets of at most leaf_size points, but at MAX_LEVEL),
        # with their boxes
        self.groups = self.leaves[np.argsort(self.node_start[self.leaves])]
        gs = self.node_start[self.groups]
        self.group_lo = np.minimum.reduceat(xs, gs)
        self.group_hi = np.maximum.reduceat(xs, gs)

    def accelerations(self, G: float, eps: float, theta: float) -> np.ndarray:
        """a (n, 3) of every point, in the caller's order. The groups are taken
        :data:`GROUP_CHUNK` at a time (memory stays bounded for a million bodies), fewer where
        their traversal's frontier would outgrow FRONTIER_LIMIT (a small opening angle opens
        nearly every node for every group). Raises :class:`TooManyInteractions` as soon as
        the interactions so far, scaled to every group, exceed :func:`interaction_limit`."""
        a = np.zeros((len(self.x), 3))
        # every source as a row (x, y, z, mass): the nodes' monopoles, then the points, then an
        # empty one (no mass, far away) that pads the dense blocks (:func:`_pull_groups`)
        where = np.concatenate([self.node_com, self.x, np.full((1, 3), PAD_AWAY)])
        mass = np.concatenate([self.node_mass, self.m, [0.0]])
        tables = np.concatenate([where, mass[:, None]], axis=1)
        total, done, size, groups = 0, 0, GROUP_CHUNK, len(self.groups)
        while done < groups:
            chunk = np.arange(done, min(done + size, groups))
            try:
                total = self._accelerate(a, chunk, tables, G, eps, theta, total, groups)
            except _FrontierFull:
                if size == 1:
                    raise
                size = max(1, size // 8)
                continue
            done += len(chunk)
        out = np.empty_like(a)
        out[self.order] = a
        return out

    def _accelerate(self, a: np.ndarray, chunk: np.ndarray, tables: np.ndarray, G: float,
                    eps: float, theta: float, total: int = 0,
                    groups_in_all: int | None = None) -> int:
        """The accelerations of the points of the groups ``chunk`` (consecutive indices, the
        first ``chunk[0]`` done with ``total`` interactions). Returns the interactions so far
        (refused before any is evaluated when, scaled to ``groups_in_all``, they would pass
        :func:`interaction_limit`; and as :class:`_FrontierFull` when its sources would
        outgrow 4 FRONTIER_LIMIT rows)."""
        (far_g, far_n), (near_g, near_l) = self.interactions(theta, chunk)
        sources = len(far_n) + int(self.node_count[near_l].sum())
        if sources > 4 * FRONTIER_LIMIT:
            raise _FrontierFull(sources)
        # each group's sources, as rows of one table of nodes then points: its far nodes'
        # monopoles and its near leaves' points, sorted by group (a radix sort of small keys)
        n_nodes = len(self.node_mass)
        group_of = np.concatenate([far_g, np.repeat(near_g, self.node_count[near_l])]) \
            - chunk[0]
        source = np.concatenate([far_n, n_nodes + _ranges(self.node_start[near_l],
                                                          self.node_count[near_l])])
        key = group_of.astype(np.uint16 if len(chunk) <= 1 << 16 else np.int64)
        source = source[np.argsort(key, kind="stable")]
        groups = self.groups[chunk]
        per_group = np.bincount(key, minlength=len(groups))
        count = self.node_count[groups]
        total += int((count * per_group).sum())  # interactions: points times sources
        scale = (groups_in_all or len(self.groups)) / (chunk[-1] + 1)
        if total * scale > interaction_limit(len(self.x)):
            raise TooManyInteractions(int(total * scale))
        _pull_groups(a, self.x, self.node_start[groups], count, tables, source, per_group,
                     G, eps)
        return total

    def interactions(self, theta: float, groups: np.ndarray | None = None
                     ) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """The traversal: (group, far node) pairs and (group, near leaf) pairs; groups are
        indices into :attr:`groups`. A node is far from a group when its side is under theta
        times the distance from its centre of mass to the group's box (so from each of its
        points). Raises :class:`TooManyInteractions` (a :class:`_FrontierFull`) rather than
        hold more than FRONTIER_LIMIT (group, node) pairs at once in its frontier, or list
        more than 4 FRONTIER_LIMIT."""
        far_b, far_n, near_b, near_l = [], [], [], []
        group = np.arange(len(self.groups)) if groups is None else np.asarray(groups)
        node = np.zeros(len(group), np.int64)
        held = 0  # the pairs listed so far
        while len(group):
            com = self.node_com[node]
            gap = np.maximum(np.maximum(self.group_lo[group] - com, com - self.group_hi[group]),
                             0.0)
            far = self.node_size[node] < theta * np.sqrt(np.einsum("ij,ij->i", gap, gap))
            leaf = ~far & (self.node_children[node] == 0)
            far_b.append(group[far])
            far_n.append(node[far])
            near_b.append(group[leaf])
            near_l.append(node[leaf])
            held += len(far_n[-1]) + len(near_l[-1])
            opened = ~far & ~leaf
            b, nd = group[opened], node[opened]
            k = self.node_children[nd]
            if int(k.sum()) > FRONTIER_LIMIT or held > 4 * FRONTIER_LIMIT:
                raise _FrontierFull(max(int(k.sum()), held))
            group = np.repeat(b, k)
            node = _ranges(self.node_child[nd], k)
        return ((np.concatenate(far_b), np.concatenate(far_n)),
                (np.concatenate(near_b), np.concatenate(near_l)))


def _ranges(starts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """The concatenation of arange(s, s + c) for each (s, c)."""
    total = int(counts.sum())
    return np.repeat(starts - (np.cumsum(counts) - counts), counts) + np.arange(total)


def _pull_groups(a: np.ndarray, x: np.ndarray, start: np.ndarray, count: np.ndarray,
                 tables: np.ndarray, source: np.ndarray, per_group: np.ndarray, G: float,
                 eps: float) -> None:
    """The accelerations of groups of points (runs ``start``, ``count`` of ``x``) by their
    sources (``source``: rows of ``tables``, (x, y, z, mass) per source, grouped in order,
    ``per_group`` each): G sum m d / (|d|^2 + eps^2)^(3/2), d = source - point (a source at the
    point itself adds nothing), into ``a``. Group-major: a group's sources are gathered once
    and met by all its points in a dense block — the points of a bucket share their
    interaction list, which point by point was gathered once per point (up to LEAF_SIZE times
    each). A block holds groups whose source counts round up to the same multiple of
    PAD_TO (padded to it with the empty last source) and, among those, like point counts; a
    bucket too big for one block (many points in one MAX_LEVEL cell) gives its points a slice
    at a time. Each point's sum runs along its own row alone, so it is the same whichever
    groups share its block (a traversal taken in parts gives the same bits)."""
    if not len(per_group):
        return
    pad = len(tables) - 1
    src_start = np.cumsum(per_group) - per_group
    padded = -(-per_group // PAD_TO) * PAD_TO
    order = np.lexsort((count, padded))  # by padded width, then by points: little padding
    width, points = padded[order], count[order]
    lo, n = 0, len(order)
    while lo < n:
        hi = _block_end(width, points, lo)
        g = order[lo:hi]
        w, most = int(width[lo]), int(points[hi - 1])
        at = np.arange(w)
        # (every bucket has sources: its own leaf is never far from its own box)
        rows = np.where(at < per_group[g, None],
                        source[np.minimum(src_start[g, None] + at, len(source) - 1)], pad)
        src = np.take(tables, rows, axis=0)  # (g, s, 4): one gather of each source's row
        mass = (G * src[:, :, 3])[:, None, :]
        step = max(1, BLOCK // max(1, len(g) * w))
        for first in range(0, most, step):
            k = np.arange(first, min(first + step, most))
            points_at = start[g, None] + np.minimum(k, count[g, None] - 1)  # (last repeats)
            at_x = np.take(x, points_at, axis=0)
            d = [src[:, None, :, c] - at_x[:, :, None, c] for c in range(3)]
            r2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2] + eps * eps
            with np.errstate(divide="ignore", invalid="ignore"):
                pull = np.where(r2 > 0.0, mass / (r2 * np.sqrt(r2)), 0.0)
            # (a sum along each row: einsum's changes with the block's shape past 8,192)
            acc = np.stack([np.multiply(dc, pull, out=dc).sum(axis=2) for dc in d], axis=2)
            real = k < count[g, None]
            a[points_at[real]] = acc[real]
        lo = hi


def _block_end(width: np.ndarray, points: np.ndarray, lo: int) -> int:
    """The end of the run of groups from ``lo`` (sorted by ``width``, their padded source
    counts, then by ``points``) of ``lo``'s width whose dense block (groups x most points x
    width) holds at most BLOCK pairs (at least one group)."""
    same = int(np.searchsorted(width, width[lo], side="right"))
    take = np.arange(1, same - lo + 1) * points[lo:same] * int(width[lo]) <= BLOCK
    return lo + max(1, int(np.count_nonzero(take)))  # (the products grow along the run)


def accelerations(x: np.ndarray, m: np.ndarray, G: float, eps: float,
                  theta: float) -> np.ndarray:
    """a (n, 3) [m/s^2] of every point: the exact sum for theta 0 or few points, else the
    tree code."""
    x = np.asarray(x, np.float64)
    m = np.asarray(m, np.float64)
    if theta == 0.0 or len(x) < EXACT_BELOW:
        return exact_accelerations(x, m, G, eps)
    return Octree(x, m).accelerations(G, eps, theta)
