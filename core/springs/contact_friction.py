"""Contacts of a spring mesh in the implicit step: which pressed vertices its filter holds,
static and kinetic Coulomb friction, and which contacts the step's impulses cannot hold.

Baraff & Witkin's filter (:class:`.implicit_parts.VelocityFilter`) holds a pressed vertex on its
surface along the normal; a vertex sliding slower than a stick speed is held whole (static
friction, as a pin). After the solve, the impulses that held each vertex (the solve's residual
on its row) tell whether the contact could give them: a holding impulse outside the friction
cone slips, a contact with a two-way coupled body that pulls lets go. Kinetic friction on the
sliding vertices is one more impulse, capped by mu times the normal impulse.
"""
from __future__ import annotations

import numpy as np

from .implicit_parts import BaraffWitkinSystem, VelocityFilter, diagonal_filter


def split(vectors: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each row of ``vectors`` (m, 3) split along its unit ``normal`` (m, 3): the normal
    components (m,) and the tangential parts (m, 3)."""
    along = np.einsum("ij,ij->i", vectors, normal)
    return along, vectors - along[:, None] * normal


def contact_filter(system: BaraffWitkinSystem, t: float, h: float, v0: np.ndarray,
                   f0: np.ndarray, stick_speed: float, slipping: np.ndarray | None = None,
                   leaving: np.ndarray | None = None) -> VelocityFilter:
    """Baraff & Witkin's filter: pinned vertices move with their pins at the step's end;
    contacts hold their vertices on the surface where the forces ``f0`` press them into it.
    A pressed vertex that is not sliding along its surface (slower than ``stick_speed``) is
    held by static friction: its whole velocity becomes the surface's, as a pin's (the solve
    then finds the friction impulse that holds it, :func:`released` checks it against the
    cone). ``slipping``: vertices static friction was found not to hold; ``leaving``: vertices
    the contact was found to pull (:func:`released`)."""
    free = system.free.copy()
    given = np.where(free[:, None], 0.0, system.pinned_velocity(t + h) - v0)
    contact = system.contact
    pressed, normal, stuck = np.zeros(0, np.int64), np.zeros((0, 3)), None
    if len(contact):
        push = np.einsum("ij,ij->i", f0[contact.index], contact.normal)
        # only where forces press inwards, or where the vertex is held (landing: the solver's
        # re-solve of a step in which it hit the surface, SpringMeshSolver.advance)
        keep = ((push < 0.0) | contact.held) & system.free[contact.index]
        if leaving is not None:
            keep &= ~np.isin(contact.index, leaving)
        pressed, normal = contact.index[keep], contact.normal[keep]
        vn = np.einsum("ij,ij->i", v0[pressed], normal)
        given[pressed] = (contact.normal_speed[keep] - vn)[:, None] * normal
        _, slide = split(v0[pressed] - contact.surface_velocity[keep], normal)
        stuck = (contact.friction[keep] > 0.0) & \
            (np.einsum("ij,ij->i", slide, slide) <= stick_speed ** 2)
        if slipping is not None:
            stuck &= ~np.isin(pressed, slipping)
        stuck |= contact.wedged[keep]
        given[pressed[stuck]] -= slide[stuck]
        free[pressed[stuck]] = False
    sliding = slice(None) if stuck is None else ~stuck
    return VelocityFilter(given, free[:, None].astype(np.float64), pressed, normal, contact,
                          diagonal_filter(free, pressed[sliding], normal[sliding]), stuck)


def released(constraints: VelocityFilter, reaction: np.ndarray, bodies: np.ndarray,
             pull_share: float) -> tuple[np.ndarray, np.ndarray]:
    """The pressed vertices the step's contact impulses (``reaction`` (n, 3) [N s], the
    solve's constraint impulses) cannot hold: ``(slipping, leaving)``. Slipping: stuck ones
    whose holding impulse leaves the friction cone, its tangential part above mu times its
    normal part (not wedged ones: no one way to slide). Leaving: those pressed on ``bodies``
    (colliders, as in ``contact.collider``) that the contact pulls (more than ``pull_share``
    of the largest push)."""
    pressed, contact = constraints.pressed, constraints.contact
    rn, rt = split(reaction[pressed], constraints.normal)
    pulls = rn < -pull_share * np.abs(rn).max(initial=0.0)
    pulls &= np.isin(contact.collider[constraints.rows], bodies)
    held = np.zeros(0, np.int64) if constraints.stuck is None else np.flatnonzero(
        constraints.stuck & ~pulls & ~contact.wedged[constraints.rows])
    mu = contact.friction[constraints.rows[held]]
    out = np.einsum("ij,ij->i", rt[held], rt[held]) > (mu * np.maximum(rn[held], 0.0)) ** 2
    return pressed[held[out]], pressed[pulls]


def on_bodies(constraints: VelocityFilter, bodies: np.ndarray) -> bool:
    """Whether some pressed vertex presses on one of ``bodies`` (two-way coupled)."""
    return bool(len(bodies)) and bool(
        np.isin(constraints.contact.collider[constraints.rows], bodies).any())


def beyond_cone(constraints: VelocityFilter, reaction: np.ndarray,
                slipping: np.ndarray) -> np.ndarray:
    """(n, 3) [N s] the part of the holding impulses (``reaction``) on the ``slipping``
    vertices (stuck in ``constraints``) beyond the friction cone: their tangential part less mu
    times their normal part along it (zero on every other vertex)."""
    rows = np.flatnonzero(np.isin(constraints.pressed, slipping))
    vertex = constraints.pressed[rows]
    rn, rt = split(reaction[vertex], constraints.normal[rows])
    size = np.sqrt(np.einsum("ij,ij->i", rt, rt))
    mu = constraints.contact.friction[constraints.rows[rows]]
    keep = mu * np.maximum(rn, 0.0) / np.where(size > 0.0, size, 1.0)
    out = np.zeros_like(reaction)
    out[vertex] = (1.0 - np.minimum(keep, 1.0))[:, None] * rt
    return out


def kinetic_stop(v1: np.ndarray, constraints: VelocityFilter, reaction: np.ndarray,
                 mass: np.ndarray) -> np.ndarray:
    """Coulomb friction on the sliding pressed vertices of ``constraints`` (the stuck ones'
    friction was in the solve): the velocity change (n, 3) that would stop each one's sliding
    at ``v1`` (n, 3), capped by mu times the constraint's normal impulse (``reaction``, the
    residual of the unfiltered system, along n) over its ``mass`` (n, 1)."""
    sliding = constraints.sliding
    pressed, normal = constraints.pressed[sliding], constraints.normal[sliding]
    row = constraints.rows[sliding]
    mu = constraints.contact.friction[row]
    impulse = np.maximum(0.0, np.einsum("ij,ij->i", reaction[pressed], normal))
    _, vt = split(v1[pressed] - constraints.contact.surface_velocity[row], normal)
    speed = np.sqrt(np.einsum("ij,ij->i", vt, vt))
    stop = np.minimum(speed, mu * impulse / mass[pressed, 0])
    out = np.zeros_like(v1)
    out[pressed] = -(stop / np.where(speed > 1e-12, speed, np.inf))[:, None] * vt
    return out
