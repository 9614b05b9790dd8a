"""Contact points of the rigid narrow phase and the small geometric helpers its shape pairs share.

Conventions (every pair function of :mod:`.narrow`): shape A and shape B of pair i; the normal
is a unit vector from A towards B; the separation of a point is the signed distance between the
two surfaces along that normal (negative: overlap); the point lies midway between the surfaces.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import cross

# Below this squared sine of the angle between two directions they count as parallel: their
# cross product then carries rounding rather than direction.
PARALLEL_SQ = 1e-12
FEATURE_COUNT = 256  # feature ids lie in [0, FEATURE_COUNT)


@dataclass(frozen=True)
class PairContacts:
    """Contact points of a batch of shape pairs, ordered by pair.

    Attributes:
        pair: (k,) int64 index of the input pair each point belongs to.
        point: (k, 3) world point midway between the two surfaces [m].
        normal: (k, 3) unit normal from shape A towards shape B.
        separation: (k,) signed distance between the surfaces along the normal [m]
            (< 0: overlap).
        feature: (k,) int64 in [0, 256): which features touch. It stays the same while the same
            features touch (a persistent id to warm-start impulses) and differs between the
            points of one pair.
    """

    pair: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    separation: np.ndarray
    feature: np.ndarray

    @classmethod
    def empty(cls) -> PairContacts:
        return cls(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0),
                   np.zeros(0, np.int64))

    def swapped(self) -> PairContacts:
        """The same points with A and B exchanged: the normals point the other way (feature ids
        are kept: they name the same touching features)."""
        return PairContacts(self.pair, self.point, -self.normal, self.separation, self.feature)

    def __len__(self) -> int:
        return len(self.pair)

    @classmethod
    def concatenate(cls, parts: list[PairContacts]) -> PairContacts:
        """One set from several, ordered by pair (stable: each pair's points keep their order)."""
        parts = [p for p in parts if len(p)]
        if not parts:
            return cls.empty()
        pair = np.concatenate([p.pair for p in parts])
        order = np.argsort(pair, kind="stable")
        return cls(pair[order], *(np.concatenate([getattr(p, k) for p in parts])[order]
                                  for k in ("point", "normal", "separation", "feature")))


def as_margin(margin, m: int) -> np.ndarray:
    """(m,) margins [m] from a scalar or an (m,) array."""
    return np.broadcast_to(np.asarray(margin, dtype=np.float64), (m,))


def collect(pair: np.ndarray, point: np.ndarray, normal: np.ndarray, separation: np.ndarray,
            feature: np.ndarray, keep: np.ndarray) -> PairContacts:
    """Contacts from per-pair slot arrays: (m, s, ...) values, keep (m, s) bool; points come
    out ordered by pair, then by slot."""
    row, slot = np.nonzero(keep)
    normal = normal[row] if normal.ndim == 2 else normal[row, slot]
    return PairContacts(pair[row].astype(np.int64), point[row, slot], normal,
                        separation[row, slot], feature[row, slot].astype(np.int64))


def dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-wise dot products of (..., 3) arrays."""
    return np.einsum("...i,...i->...", u, v)


def unit(v: np.ndarray, fallback: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unit vectors, lengths) of (m, 3) vectors; rows of zero length take ``fallback``."""
    length = np.sqrt(dot(v, v))
    ok = length > 0.0
    return np.where(ok[:, None], v / np.where(ok, length, 1.0)[:, None], fallback), length


def perpendicular(v: np.ndarray) -> np.ndarray:
    """(m, 3) unit vectors perpendicular to the unit vectors v (m, 3)."""
    helper = np.where((np.abs(v[:, 0]) < 0.57)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    p = cross(v, helper)
    return p / np.linalg.norm(p, axis=1)[:, None]


def local(rot: np.ndarray, v: np.ndarray) -> np.ndarray:
    """World vectors v (m, 3) in the frames whose axes are the columns of rot (m, 3, 3)."""
    return np.einsum("mji,mj->mi", rot, v)


def world(rot: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Local vectors v (m, ..., 3) of frames rot (m, 3, 3) in world axes."""
    return np.einsum("mij,m...j->m...i", rot, v)


def closest_segments(pa, a, la, pb, b, lb) -> tuple[np.ndarray, np.ndarray]:
    """Parameters of the closest points of segments pa + s a, s in [-la, la] and pb + t b,
    t in [-lb, lb] (unit directions a, b (m, 3); half lengths (m,), zero allowed), Ericson's
    clamping (Real-Time Collision Detection 5.1.9). Parallel segments take s at B's centre.

    Returns:
        (s (m,), t (m,)) [m].
    """
    r = pa - pb
    ab, ar, br = dot(a, b), dot(a, r), dot(b, r)
    denom = 1.0 - ab * ab
    skew = denom > PARALLEL_SQ
    s = np.where(skew, (ab * br - ar) / np.where(skew, denom, 1.0), -ar)
    s = np.clip(s, -la, la)
    t_free = ab * s + br
    t = np.clip(t_free, -lb, lb)
    s = np.where(t != t_free, np.clip(ab * t - ar, -la, la), s)
    return s, t


def region(s: np.ndarray, half: np.ndarray) -> np.ndarray:
    """0, 1, 2: a parameter s (m,) at the low end, inside, at the high end of [-half, half]."""
    return np.where(s >= half, 2, np.where(s <= -half, 0, 1))


def round_pair(pa, ra, pb, rb, fallback) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Contact of spheres of radius ra, rb (m,) about points pa, pb (m, 3): the normal from pa
    to pb (``fallback`` where they coincide), the separation and the midway point.

    Returns:
        (normal (m, 3), separation (m,) [m], point (m, 3) [m]).
    """
    n, dist = unit(pb - pa, fallback)
    sep = dist - ra - rb
    point = 0.5 * (pa + pb) + (0.5 * (ra - rb))[:, None] * n
    return n, sep, point
