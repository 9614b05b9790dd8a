"""The rigid bodies as other systems coupled to them see them (:mod:`physanim.core.world`):
their inertia at a frame's end, and the impulses those systems hand back."""
from __future__ import annotations

import numpy as np

from ..transforms import cross
from ..world import BodyInertia
from . import dynamics
from . import quaternion as quat
from .model import RigidBodyModel, RigidBodyState


def bodies(model: RigidBodyModel, state: RigidBodyState, momentum0: np.ndarray | None = None
           ) -> dict[str, BodyInertia]:
    """Each dynamic body's mass, world inertia tensor, centre of mass and velocity now, by
    name, and its velocity at the frame's start from its momentum then (``momentum0``, (n, 3);
    None: now's)."""
    p0 = state.body_P if momentum0 is None else momentum0
    d = np.nonzero(~model.body_kinematic)[0]
    rot = quat.to_matrix(state.body_q[d])
    inertia = rot @ model.body_inertia[d] @ rot.transpose(0, 2, 1)
    spin = dynamics.angular_velocity(state.body_q[d], model.body_inv_inertia[d], state.body_L[d])
    return {model.body_name[i]: BodyInertia(
        float(model.body_mass[i]), inertia[k], state.body_x[i].copy(),
        np.concatenate([state.body_P[i] / model.body_mass[i], spin[k]]),
        p0[i] / model.body_mass[i]) for k, i in enumerate(d)}


def absorb(model: RigidBodyModel, state: RigidBodyState, reactions) -> None:
    """Impulses other systems' constraints gave the bodies over the frame just ended (a cloth a
    body hangs from, :class:`~physanim.core.world.Reaction`): added to their momenta, each at
    its point (about the centre before the move), and the move they made to its pose; a body
    asleep wakes. Names of no dynamic body are ignored."""
    index = {name: i for i, name in enumerate(model.body_name)}
    for r in reactions:
        i = index.get(r.body)
        if i is None or model.body_kinematic[i]:
            continue
        state.body_P[i] += r.impulse.sum(axis=0)
        state.body_L[i] += cross(r.point - state.body_x[i], r.impulse).sum(axis=0)
        state.body_x[i] += r.move[:3]
        state.body_q[i] = quat.normalized(quat.multiply(
            quat.from_rotation_vector(r.move[3:]), state.body_q[i]))
        if state.body_asleep[i] and np.any(r.impulse):
            state.body_asleep[i], state.body_slow[i] = False, 0
