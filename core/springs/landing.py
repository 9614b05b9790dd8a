"""Landing: a sub-step whose vertices hit a collider is solved again with them as constraints
landing on it (their neighbours feel the stop through the springs, instead of a projection
after the fact that stretches stiff springs: energy from nowhere). Vertices whose faces the
colliders' features must lift land the same way. Used by :mod:`.solver`."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..contact import Contacts
from ..contact.features import FaceSet, NearPairs, keep_off_features

ESTIMATE_ROUNDS = 2  # detection rounds that estimate where the faces' vertices must land
# [m] a step whose faces the features lift by less than this everywhere is not solved again:
# the lift is left to the features' pass after the step (a face sagging onto a corner it rests
# on, a fraction of a millimetre each sub-step, would cost a whole solve each time)
LAND_LIFT = 1e-3
FLAT = ("HALF_SPACE", "PLANE")  # collider shapes on which a small hit is a touch (touches)


def contacts(base: Contacts, hit: Contacts, x0: np.ndarray, h: float, free: np.ndarray,
             faced: Contacts | None = None, touch: np.ndarray | None = None
             ) -> Contacts | None:
    """Contacts for re-solving a step in which free vertices hit a collider (``hit``: their
    first collisions, from :func:`~..contact.respond`): each becomes a held constraint whose
    normal velocity is the one that takes it from its start x0 to where the collision put it
    in the step h [s] — merged with ``base`` (the step's resting contacts, or the last round's
    set; a resting vertex that was hit lands instead). ``faced``: vertices the colliders'
    features push off the faces (:func:`off_features`), which land where that puts them even
    when held already (the last round left their faces short). ``touch``: (k,) the hits that
    are touches (:func:`touches`): when every new one is, none lands (the projection after the
    step stands). None when no vertex needs to land anew."""
    keep = free[hit.index] & ~np.isin(hit.index, base.index[base.held])
    if touch is not None and not np.any(keep & ~touch):
        keep = np.zeros_like(keep)
    land = [hit.take(keep)]
    if faced is not None and len(faced):
        land.append(faced.take(free[faced.index]))
    if not sum(len(c) for c in land):
        return None
    for c in land:
        vn = np.einsum("ij,ij->i", c.point - x0[c.index], c.normal) / h
        base = base.merged(replace(c, normal_speed=vn, held=np.ones(len(c), bool)))
    return base


def flat(paths: list, bodies) -> np.ndarray:
    """(c,) bool per collider path: flat (FLAT shapes) and not a body stepped first
    (``bodies``: their names) — where a small hit is a touch (:func:`touches`)."""
    return np.array([p.frame.shape in FLAT and p.frame.name not in bodies for p in paths], bool)


def touches(hit: Contacts, solved: np.ndarray, placed: np.ndarray, rest_speed: float,
            flat: np.ndarray) -> np.ndarray:
    """(k,) bool per hit: a touch, not a landing — the collision response moved the vertex
    less than LAND_LIFT from where the solve put it (``solved``; ``placed``: after the
    response, (n, 3) each) and changed its normal speed by less than ``rest_speed`` (what it
    takes as contact, not a bounce), on a collider that ``flat`` (bool per collider) marks:
    a flat one (a half-space or plane) that is not a body stepped first (the solve's impulses
    are what a body takes back).

    A step whose hits are all touches is not solved again. In a cloth lying on the ground,
    vertices whose forces did not press them in at the step's start dip a fraction of a
    millimetre under it, and each such dip cost a whole solve (90 of the 125 re-solves of the
    self-collision bench); on a flat surface the projection moves the vertex along the one
    normal the landing would, so the re-solve only changed how its neighbours feel a
    sub-millimetre stop. On a curved collider it also changes how a drape settles: with its
    3 touches on Suzanne projected, the Suzanne drape buzzed at 3 cm/s (a vertex flipping on
    and off a resting contact every sub-step) and never slept, 3 x the time."""
    moved = placed[hit.index] - solved[hit.index]
    small = np.einsum("ij,ij->i", moved, moved) < LAND_LIFT ** 2
    on_flat = (hit.collider >= 0) & flat[np.maximum(hit.collider, 0)] if len(flat) else \
        np.zeros(len(hit), bool)
    return small & (np.abs(hit.impulse) < rest_speed) & on_flat


def off_features(paths: list, faces: FaceSet, x0: np.ndarray, x: np.ndarray, v: np.ndarray,
                 inv_mass: np.ndarray, s0: float, s1: float,
                 rest_speed: float, near: NearPairs | None = None, bodies: frozenset = frozenset()
                 ) -> tuple[Contacts, np.ndarray, np.ndarray]:
    """Where keeping the colliders' features off the faces puts a step's vertices (x, v at
    its end; x0 at its start), as hits to land on, and that projection (positions,
    velocities). No hits when every vertex moves less than LAND_LIFT and none of them off a
    collider named in ``bodies`` (bodies stepped first: the solve's impulses are what they take
    back, so a lift off them always lands)."""
    placed, pushed = x.copy(), v.copy()
    kept = keep_off_features(paths, faces, x0, placed, pushed, inv_mass, s0, s1, rest_speed,
                             ESTIMATE_ROUNDS, near)
    moved = np.nonzero(np.any(placed != x, axis=1))[0]
    moved = moved[np.isin(moved, kept.index)]
    rows = np.searchsorted(kept.index, moved)
    if len(moved) and np.max(np.linalg.norm(placed[moved] - x[moved], axis=1)) < LAND_LIFT \
            and not any(paths[c].frame.name in bodies for c in np.unique(kept.collider[rows])):
        moved, rows = moved[:0], rows[:0]
    return Contacts.of(moved, placed[moved], kept.normal[rows], kept.surface_velocity[rows],
                       kept.friction[rows], kept.restitution[rows],
                       collider=kept.collider[rows]), placed, pushed


def bounce(v: np.ndarray, landing: Contacts, rest_speed: float) -> None:
    """After a re-solved step the landing vertices are on the surface, still approaching it at
    their landing speed: they leave it at restitution times that speed (relative to the
    surface; a bounce slower than ``rest_speed`` ends in contact), as the collision pass would
    have made them."""
    sel = landing.held
    idx, n = landing.index[sel], landing.normal[sel]
    surface_vn = np.einsum("ij,ij->i", landing.surface_velocity[sel], n)
    approach = landing.normal_speed[sel] - surface_vn
    out = -landing.restitution[sel] * np.minimum(approach, 0.0)
    out = np.where(out < rest_speed, 0.0, out)
    vn = np.einsum("ij,ij->i", v[idx], n)
    v[idx] += (surface_vn + out - vn)[:, None] * n
