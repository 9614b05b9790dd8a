"""A spring mesh as its integrator sees it during one sub-step."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..contact import ContactForce, Contacts
from ..forces import ParticleView
from ..transforms import scale_rows
from .model import SpringMeshState


@dataclass
class SubstepForces:
    """The forces of one sub-step, by what the solvers need of them.

    Attributes:
        all: every force object (``apply(view, f_out)``), in the order they accumulate.
        stiff: those with Jacobian blocks (``linearize(view)``), for the implicit solve.
        potentials: those with a potential energy (``energy(x)``) [J].
        gravity: (3,) [m/s^2].
    """

    all: list
    stiff: list
    potentials: list
    gravity: np.ndarray


class MeshOde:
    """The spring mesh as integrators see it: flat y = [x, v] with derivative [v, f/m], plus
    the richer interface of the Baraff-Witkin stepper. Pinned vertices move with their targets.

    ``contact``: the vertices touching colliders. Explicit integrators see them as a constraint
    on the accumulated forces (``constraint``, a :class:`ContactForce`); the implicit stepper
    enforces ``contact`` as velocity constraints instead (``constraint`` None). ``bodies``: the
    colliders (``contact.collider`` values) that are two-way coupled bodies (None: none).
    ``coupled``: vertices are attached to bodies that take their impulses back (two-way; a
    second-order stepper then takes a backward Euler step: :mod:`.bdf2`)."""

    def __init__(self, state: SpringMeshState, mass: np.ndarray, free: np.ndarray,
                 forces: SubstepForces, pin_v: np.ndarray, contact: Contacts,
                 constraint: ContactForce | None, bodies: np.ndarray | None = None,
                 coupled: bool = False):
        self.state = state
        self.mass = mass
        self.free = free
        self.forces = forces
        self.contact = contact
        self.constraint = constraint
        self.bodies = np.zeros(0, np.int64) if bodies is None else bodies
        self.coupled = coupled
        self._pin_v = pin_v
        self.n = len(mass)
        self.dim = 6 * self.n

    # --- the Witkin & Baraff interface ---------------------------------------------------------
    def get_state(self) -> np.ndarray:
        return np.concatenate([self.state.x.ravel(), self.state.v.ravel()])

    def set_state(self, y: np.ndarray) -> None:
        n = self.n
        self.state.x = y[:3 * n].reshape(n, 3).copy()
        self.state.v = y[3 * n:].reshape(n, 3).copy()

    def forces_at(self, t: float, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        f = np.zeros_like(x)
        view = ParticleView(x, v, self.mass, t)
        for force in self.forces.all:
            force.apply(view, f)
        if self.constraint is not None:
            self.constraint.constrain(view, f)  # after the forces: cancels what presses inward
        return f

    def derivative(self, t: float, y: np.ndarray) -> np.ndarray:
        n = self.n
        x, v = y[:3 * n].reshape(n, 3), y[3 * n:].reshape(n, 3)
        a = self.forces_at(t, x, v) / self.mass[:, None]
        a[~self.free] = 0.0
        v = np.where(self.free[:, None], v, self._pin_v)
        return np.concatenate([v.ravel(), a.ravel()])

    # --- Baraff-Witkin extras ------------------------------------------------------------------
    def energy(self, x: np.ndarray, v: np.ndarray) -> float:
        """Kinetic + gravitational + spring + bending energy [J] of the free vertices' motion
        (what an implicit step must not increase when nothing drives the mesh)."""
        m = self.mass
        e = 0.5 * float(np.sum(scale_rows(v, m) * v))  # (m v) v, by columns
        if np.any(self.forces.gravity):
            e -= float(np.sum(m * (x @ self.forces.gravity)))
        for force in self.forces.potentials:
            e += force.energy(x)
        return e

    def weight_norm(self) -> float:
        g = self.forces.gravity
        return float(np.linalg.norm(g) * np.linalg.norm(self.mass[self.free])) or \
            float(np.linalg.norm(self.mass))

    def pinned_velocity(self, t: float) -> np.ndarray:
        return self._pin_v

    def linearize(self, t, x, v) -> list:
        """Jacobian blocks of every stiff force at (x, v), built once per implicit step."""
        view = ParticleView(x, v, self.mass, t)
        return [force.linearize(view) for force in self.forces.stiff]
