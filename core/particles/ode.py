"""The particles as an ODE system: what an integrator sees of a sub-step (Witkin & Baraff)."""
from __future__ import annotations

import numpy as np

from ..contact import ContactForce
from ..forces import Gravity, HardConstraints, ParticleView
from ..transforms import divide_rows
from .model import ParticleState


class ParticleOde:
    """Witkin & Baraff's particle system seen by an integrator: dim, get/set state, derivative;
    to symplectic Euler as its points (:class:`~..integrators.PointSystem`)."""

    def __init__(self, state: ParticleState, forces: list, contact: ContactForce,
                 constraints: HardConstraints | None = None,
                 into: tuple[np.ndarray, np.ndarray] | None = None):
        self.state = state
        self.into = into  # (x, v) a step writes the new state into (None: new arrays)
        self.forces = forces
        self.contact = contact
        self.constraints = constraints
        n = state.particle_count
        self.dim = 6 * n
        self._n = n

    def get_state(self) -> np.ndarray:
        return np.concatenate([self.state.particle_x.ravel(), self.state.particle_v.ravel()])

    def set_state(self, y: np.ndarray) -> None:
        n = self._n
        # views of the integrator's fresh result (it keeps no reference to it)
        self.state.particle_x = y[:3 * n].reshape(n, 3)
        self.state.particle_v = y[3 * n:].reshape(n, 3)

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        return self.state.particle_x, self.state.particle_v

    def new_points(self) -> tuple[np.ndarray, np.ndarray] | None:
        return self.into

    def set_points(self, x: np.ndarray, v: np.ndarray) -> None:
        self.state.particle_x, self.state.particle_v = x, v

    def acceleration(self, t: float, x: np.ndarray, v: np.ndarray,
                     out: np.ndarray | None = None) -> np.ndarray:
        """(n, 3) the accelerations at positions ``x`` and velocities ``v`` (into ``out``)."""
        forces = self.forces
        if len(forces) == 1 and isinstance(forces[0], Gravity) and self.constraints is None \
                and not len(self.contact.contacts):  # g itself: no m g / m, no accumulator
            return forces[0].acceleration(len(x), out)
        view = ParticleView(x, v, self.state.particle_mass, t)
        if forces and isinstance(forces[0], Gravity):  # the accumulator starts as m g
            f = forces[0].force(view)
            forces = forces[1:]
        else:
            f = np.zeros((self._n, 3))  # clear the accumulator, then every force adds in
        for force in forces:
            force.apply(view, f)
        self.contact.constrain(view, f)  # it cancels what the forces push into surfaces
        if self.constraints is not None:  # last: holds the rods against every other force
            self.constraints.constrain(view, f)
        return divide_rows(f, self.state.particle_mass, out=f if out is None else out)

    def derivative(self, t: float, y: np.ndarray) -> np.ndarray:
        n = self._n
        out = np.empty_like(y)
        out[:3 * n] = y[3 * n:]
        self.acceleration(t, y[:3 * n].reshape(n, 3), y[3 * n:].reshape(n, 3),
                          out[3 * n:].reshape(n, 3))
        return out
