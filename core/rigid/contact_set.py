"""Contact points as the solver lays them out: manifolds (the points of one pair of bodies)
padded to S slots, ordered by colour so that no dynamic body is in two manifolds of one colour
(each colour is then one vectorised pass over a contiguous slice), with the tangents that
complete each normal."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..colouring import colour
from ..transforms import tangents


@dataclass
class ContactSet:
    """Contact points by manifold: M manifolds (the points of one pair of bodies) of S slots;
    after :meth:`coloured`, ordered by colour.

    Attributes:
        ab: (M, 2) the manifold's body rows a, b. pair: (M,) their key (lower row * N +
            higher row). valid: (M, S) the slot holds a point.
        place: (M, S, 3) each point in the frame of the pair's lower body [m] (warm starting
            matches contacts by place: :mod:`.warm`).
        normal, t1, t2: (M, S, 3) unit normal from a to b and tangents (0 in empty slots).
        ra, rb: (M, S, 3) anchors: each body's surface point from its centre of mass at the
            poses of ``q0`` (the solver's reference orientations).
        base: (M, S) [m]: the separation is base + n . (p_b - p_a), p the anchors' world
            positions (0 for the surface points as found).
        friction, restitution: (M, S) combined coefficients (friction: the geometric mean of
            the two sides'; restitution: their product, so a body bounces only where both are
            bouncy — a default, unbouncy box stays down on any collider).
        relative: (M, S) normal relative velocity [m/s] before the point's first impulse this
            frame (restitution bounces it back).
        impulse: (M, S, 3) accumulated impulse along normal, t1, t2 [N s].
        touched: (M, S) took a normal impulse this frame.
        static: (M,) one side does not move under impulses.
        colours: [(start, stop)] manifold slices in which no dynamic body appears twice.
        coupling: (M, S, S) each manifold's normal coupling K_ij = J_i M^-1 J_j^T and block its
            pseudo-inverse, set by :func:`rows` at the poses where the manifold was found (NaN
            until then; kept with the manifold: they barely change).
        subsets: (M, 2^W, W, W), W = min(S, 4): the pseudo-inverse of the coupling restricted
            to each subset of the first W slots (bit i of the subset's index: slot i), set with
            ``block`` (:func:`.manifold_blocks.subset_blocks`).
    """

    ab: np.ndarray
    pair: np.ndarray
    valid: np.ndarray
    place: np.ndarray
    normal: np.ndarray
    t1: np.ndarray
    t2: np.ndarray
    ra: np.ndarray
    rb: np.ndarray
    base: np.ndarray
    friction: np.ndarray
    restitution: np.ndarray
    relative: np.ndarray
    impulse: np.ndarray
    touched: np.ndarray
    static: np.ndarray | None = None
    colours: list | None = None
    coupling: np.ndarray | None = None
    block: np.ndarray | None = None
    subsets: np.ndarray | None = None
    rows_buffer: tuple | None = None  # what :func:`.contact_solver.rows` keeps (not pickled)

    _PER_SLOT = ("valid", "place", "normal", "t1", "t2", "ra", "rb", "base", "friction",
                 "restitution", "relative", "impulse", "touched")

    def __len__(self) -> int:
        return len(self.ab)

    def __getstate__(self):
        return {**self.__dict__, "rows_buffer": None}

    @classmethod
    def of_points(cls, a, b, pair, *, place, normal, point, xa, xb, separation, friction,
                  restitution, relative, impulse) -> ContactSet:
        """Group k points (bodies a, b (k,); ``pair`` (k,) their key) into manifolds.
        ``point`` (k, 3) world points midway between the surfaces, ``xa``, ``xb`` (k, 3) the
        bodies' centres of mass; the other arrays are per point. Each body's anchor is its own
        surface point (half the separation either side of the midpoint), so a separation
        found far ahead (a fast or fast-turning body) stays exact against a flat surface as
        the body turns: base 0."""
        slots = _manifolds(pair)
        valid = slots >= 0
        idx = np.where(valid, slots, 0)

        def pad(x):
            out = np.asarray(x)[idx]
            out[~valid] = 0
            return out

        t1, t2 = tangents(normal) if len(normal) else (normal, normal)
        surface_a = point - 0.5 * separation[:, None] * normal
        surface_b = point + 0.5 * separation[:, None] * normal
        head = idx[:, 0]
        return cls(np.stack([a[head], b[head]], axis=1), pair[head], valid, pad(place),
                   pad(normal), pad(t1), pad(t2), pad(surface_a - xa), pad(surface_b - xb),
                   np.zeros(valid.shape), pad(friction), pad(restitution), pad(relative),
                   pad(impulse), pad(impulse[:, 0] > 0.0))

    def take(self, rows: np.ndarray) -> ContactSet:
        """The manifolds ``rows`` (uncoloured)."""
        out = ContactSet(self.ab[rows], self.pair[rows],
                         *(getattr(self, f)[rows] for f in self._PER_SLOT))
        if self.block is not None:
            out.coupling, out.block = self.coupling[rows], self.block[rows]
            out.subsets = self.subsets[rows]
        return out

    @classmethod
    def join(cls, parts: list[ContactSet]) -> ContactSet:
        """The manifolds of every part, padded to the widest (uncoloured)."""
        width = max(p.valid.shape[1] for p in parts)

        def widened(x):
            if x.shape[1] == width:
                return x
            pad = [(0, 0), (0, width - x.shape[1])] + [(0, 0)] * (x.ndim - 2)
            return np.pad(x, pad)

        def square(p, x):  # a coupling or block: padded slots decoupled unit rows
            if x is None:
                return np.full((len(p), width, width), np.nan)
            if x.shape[1] == width:
                return x
            out = np.zeros((len(p), width, width))
            out[:, :x.shape[1], :x.shape[2]] = x
            extra = np.arange(x.shape[1], width)
            out[:, extra, extra] = 1.0
            return out

        out = cls(np.concatenate([p.ab for p in parts]), np.concatenate([p.pair for p in parts]),
                  *(np.concatenate([widened(getattr(p, f)) for p in parts])
                    for f in cls._PER_SLOT))
        out.coupling = np.concatenate([square(p, p.coupling) for p in parts])
        out.block = np.concatenate([square(p, p.block) for p in parts])
        out.subsets = np.concatenate([_subsets_widened(p, width) for p in parts])
        return out

    def coloured(self, dynamic: np.ndarray) -> ContactSet:
        """The manifolds ordered by colour for bodies that are ``dynamic`` (N,) now."""
        a, b = self.ab[:, 0], self.ab[:, 1]
        groups = colour(np.stack([a, b], axis=1), dynamic)
        order = np.concatenate(groups) if groups else np.zeros(0, np.int64)
        out = self.take(order)
        ends = np.cumsum([len(g) for g in groups]).tolist()
        out.colours = list(zip([0] + ends[:-1], ends))
        out.static = ~(dynamic[out.ab[:, 0]] & dynamic[out.ab[:, 1]])
        return out

    def turned(self, turn: np.ndarray) -> ContactSet:
        """The same contacts with their anchors carried by the bodies' rotations ``turn``
        (N, 3, 3) since the reference orientations (so the current ones become the
        reference); separations are unchanged."""
        a, b = self.ab[:, 0], self.ab[:, 1]
        turn_t = turn.transpose(0, 2, 1)  # (gathered contiguous: faster products)
        self.ra = np.matmul(self.ra, np.take(turn_t, a, axis=0))
        self.rb = np.matmul(self.rb, np.take(turn_t, b, axis=0))
        return self

    def world_impulses(self) -> np.ndarray:
        """(M, S, 3) each point's accumulated impulse as a world vector [N s] (on body b)."""
        i = self.impulse
        return i[..., :1] * self.normal + i[..., 1:2] * self.t1 + i[..., 2:] * self.t2


def subset_width(slots: int) -> int:
    """How many leading slots the subset blocks cover."""
    return min(slots, 4)


def _subsets_widened(part: ContactSet, width: int) -> np.ndarray:
    """The subset blocks of ``part`` for manifolds padded to ``width`` slots (NaN: not set).
    A subset's index keeps its meaning (bit i: slot i); subsets with padded slots are never
    used (a padded slot holds no point)."""
    w = subset_width(width)
    if part.subsets is not None and part.subsets.shape[1:] == (1 << w, w, w):
        return part.subsets
    out = np.full((len(part), 1 << w, w, w), np.nan)
    if part.subsets is not None:
        c, v = part.subsets.shape[1], part.subsets.shape[2]
        out[:, :c] = 0.0
        out[:, :c, :v, :v] = part.subsets
    return out


def _manifolds(key: np.ndarray) -> np.ndarray:
    """Points grouped by pair ``key``: (m, S) point indices, -1 padded."""
    if not len(key):
        return np.zeros((0, 1), np.int64)
    order = np.argsort(key, kind="stable")
    uniq, first, count = np.unique(key[order], return_index=True, return_counts=True)
    rank = np.arange(len(key)) - np.repeat(first, count)
    slots = np.full((len(uniq), int(count.max())), -1, np.int64)
    slots[np.repeat(np.arange(len(uniq)), count), rank] = order
    return slots
