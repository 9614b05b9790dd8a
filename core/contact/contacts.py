"""The typed result of every contact query and response: :class:`Contacts`, and the resting
contact constraint a system applies to its accumulated forces (:class:`ContactForce`)."""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..transforms import norm_rows, row_indices, rows_at, scale_rows, take


_NONE: dict = {}  # Contacts.none()'s instance


@dataclass(frozen=True)
class Contacts:
    """Points of one system touching colliders (k of them), one row each, sorted by index.

    Attributes:
        index: (k,) int64 indices of the points in their system's arrays.
        point: (k, 3) world point of each contact [m]: the surface point of a resting contact;
            after a hit, where the response placed the point, carried with the surface to the
            sub-step's end.
        normal: (k, 3) unit surface normals, facing the point.
        depth: (k,) how far each point is inside the surface [m] (negative: a gap).
        surface_velocity: (k, 3) the surface's velocity there [m/s].
        friction: (k,) Coulomb mu of the surface. restitution: (k,) k_r of the surface.
        impulse: (k,) normal velocity change the response gave the point [m/s] (momentum per
            unit mass; 0 for a resting contact).
        normal_speed: (k,) the normal velocity a constraint on the point prescribes [m/s]: the
            surface's own for a resting contact, the one that lands it for a landing one.
        held: (k,) bool: a constraint whatever the forces (a point landing during the step),
            not only while forces press the point into the surface.
        collider: (k,) int: which of the system's collider paths each point touches (-1:
            not known) — a collider that is another system's body takes the push back.
        wedged: (k,) bool: the point's faces rest on several of a collider's corners and
            creases facing ways no one normal stands for (:func:`~.features.resting_on_features`):
            an implicit step holds it whole, as static friction would.
        axis: ``(a, sign)`` when every normal is ``sign`` times the world axis ``a`` and every
            surface is still (resting on a ground that is not turned): the contact force is
            then computed by columns, to the same values; None: any normals.
    """

    index: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    surface_velocity: np.ndarray
    friction: np.ndarray
    restitution: np.ndarray
    impulse: np.ndarray
    normal_speed: np.ndarray
    held: np.ndarray
    collider: np.ndarray
    wedged: np.ndarray
    axis: tuple[int, float] | None = None

    @classmethod
    def none(cls) -> Contacts:
        """No contacts: one shared instance (frozen, and its arrays hold nothing to change;
        most sub-steps of most systems ask for it, several times)."""
        empty = _NONE.get(cls)
        if empty is None:
            empty = _NONE[cls] = cls.of(np.zeros(0, np.int64), np.zeros((0, 3)),
                                        np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0),
                                        np.zeros(0))
        return empty

    @classmethod
    def of(cls, index, point, normal, surface_velocity, friction, restitution, depth=None,
           impulse=None, normal_speed=None, held=None, collider=None,
           axis=None, wedged=None) -> Contacts:
        """Contacts from the arrays that always differ; the rest default to a resting contact
        (depth 0, no impulse, the surface's own normal speed, not held, not wedged). Sorts by
        index."""
        k = len(index)
        if normal_speed is None:
            normal_speed = (np.zeros(k) if axis is not None else
                            np.einsum("ij,ij->i", surface_velocity, normal))
        made = cls(np.asarray(index, np.int64), point, normal,
                   np.zeros(k) if depth is None else depth, surface_velocity,
                   np.asarray(friction, np.float64), np.asarray(restitution, np.float64),
                   np.zeros(k) if impulse is None else impulse, normal_speed,
                   np.zeros(k, bool) if held is None else held,
                   np.full(k, -1, np.int64) if collider is None
                   else np.asarray(collider, np.int64),
                   np.zeros(k, bool) if wedged is None else np.asarray(wedged, bool), axis)
        if k > 1 and np.any(made.index[1:] < made.index[:-1]):
            return made.take(np.argsort(made.index, kind="stable"))
        return made

    def __len__(self) -> int:
        return len(self.index)

    def take(self, rows) -> Contacts:
        """These contacts' rows ``rows`` (a mask or indices; kept in the given order)."""
        rows = row_indices(rows)
        return Contacts(*(take(getattr(self, name), rows) for name in _ROWS), self.axis)

    def merged(self, other: Contacts) -> Contacts:
        """These contacts with ``other``'s points replaced or added, sorted by index."""
        stay = ~np.isin(self.index, other.index)
        both = [np.concatenate([getattr(self, name)[stay], getattr(other, name)])
                for name in _ROWS]
        order = np.argsort(both[0], kind="stable")
        axis = (self.axis if self.axis == other.axis or not len(other) else
                other.axis if not stay.any() else None)
        return Contacts(*(a[order] for a in both), axis)


_ROWS = tuple(f.name for f in fields(Contacts) if f.name != "axis")  # the per-contact arrays


@dataclass(frozen=True)
class ContactForce:
    """Keeps resting points on a surface: cancels the accumulated force pushing into it and adds
    Coulomb friction: static (holds the point while the needed force is within mu |f_n|), else
    kinetic (mu |f_n| against the motion, capped so it stops, never reverses, it).

    A constraint on the total force, not a force among the others: a system calls
    :meth:`constrain` after every force has added into the accumulator.

    Args: contacts: the resting contacts at the sub-step's start. h: sub-step [s] (for the
    stopping cap).
    """

    contacts: Contacts
    h: float

    def constrain(self, p, f_out: np.ndarray) -> None:
        """Correct the accumulated forces ``f_out`` (n, 3) of the points ``p`` (a
        :class:`~physanim.core.forces.ParticleView`) in place."""
        c = self.contacts
        if len(c) == 0:
            return
        if c.axis is not None:
            self._constrain_along(p, f_out, *c.axis)
            return
        idx, normal = c.index, c.normal
        f = rows_at(f_out, idx)  # every point resting (a settled pile): no gathers
        fn = np.einsum("ij,ij->i", f, normal)
        push = np.minimum(fn, 0.0)  # only the component into the surface is cancelled
        rel = rows_at(p.v, idx) - c.surface_velocity
        # the tangential parts of the velocity and of the force (f_n drops out of both)
        # (by columns: numpy runs (k, 1) x (k, 3) broadcasts row by row; the same values)
        vt = rel - scale_rows(normal, np.einsum("ij,ij->i", rel, normal))
        ft = f - scale_rows(normal, fn)
        # friction that would stop the sliding within this step (static friction) ...
        need = scale_rows(vt, -rows_at(p.mass, idx) / self.h, out=vt)
        need -= ft
        need_mag = norm_rows(need)
        cap = c.friction * -push  # ... limited by Coulomb's mu |f_n| (kinetic friction)
        scale = np.minimum(1.0, cap / np.where(need_mag > 0.0, need_mag, np.inf))
        scale_rows(need, scale, out=need)
        need -= scale_rows(normal, push)
        if f is f_out:
            f_out += need
        else:
            f_out[idx] = f + need

    def _constrain_along(self, p, f_out: np.ndarray, a: int, sign: float) -> None:
        """:meth:`constrain` when every normal is ``sign`` times axis ``a`` and every surface is
        still: the same arithmetic by columns (the normal's other components are zeros, so
        each value equals the general route's)."""
        c = self.contacts
        idx = c.index
        f = rows_at(f_out, idx)
        v = rows_at(p.v, idx)
        push = np.minimum(f[:, a] if sign == 1.0 else f[:, a] * sign, 0.0)
        t1, t2 = (a + 1) % 3, (a + 2) % 3
        factor = rows_at(p.mass, idx) / -self.h
        need1 = v[:, t1] * factor
        need1 -= f[:, t1]
        need2 = v[:, t2] * factor
        need2 -= f[:, t2]
        need_mag = np.sqrt(need1 * need1 + need2 * need2)
        cap = c.friction * -push
        scale = np.minimum(1.0, cap / np.where(need_mag > 0.0, need_mag, np.inf))
        need1 *= scale
        need2 *= scale
        if sign != 1.0:
            push *= sign
        if f is f_out:
            f_out[:, t1] += need1
            f_out[:, t2] += need2
            f_out[:, a] -= push
        else:
            f = f.copy()
            f[:, t1] += need1
            f[:, t2] += need2
            f[:, a] -= push
            f_out[idx] = f
