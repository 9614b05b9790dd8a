"""Rigid-body scenes for the core tests (imported as ``physanim.tests.core.rigid_helpers``)."""
from __future__ import annotations

import math

import numpy as np

from physanim.core.contact import ColliderFrame
from physanim.core.rigid.mass import box_mass, sphere_mass
from physanim.core.rigid.model import RigidBodyBuilder, RigidBodySettings
from physanim.core.rigid.solver import DEFAULT_SUBSTEPS, RigidBodySolver, RigidFrameInputs

FPS = 24.0
DT = 1.0 / FPS
G = (0.0, 0.0, -9.81)


def box(name, half, position, mass=1.0, **kw) -> RigidBodySettings:
    return RigidBodySettings(name, "BOX", box_mass(half, mass=mass), half_extents=tuple(half),
                             position=tuple(position), **kw)


def sphere(name, radius, position, mass=1.0, **kw) -> RigidBodySettings:
    return RigidBodySettings(name, "SPHERE", sphere_mass(radius, mass=mass), radius=radius,
                             position=tuple(position), **kw)


def ground(friction=0.5, restitution=0.0, tilt=0.0, name="Ground") -> ColliderFrame:
    """A half-space z <= 0 (tilted by ``tilt`` [rad] about the x axis)."""
    m = np.eye(4)
    c, s = math.cos(tilt), math.sin(tilt)
    m[:3, :3] = [[1, 0, 0], [0, c, -s], [0, s, c]]
    return ColliderFrame(name, "HALF_SPACE", m, m, restitution, friction)


def world(*bodies, substeps=DEFAULT_SUBSTEPS):
    builder = RigidBodyBuilder()
    for b in bodies:
        builder.add_body(b)
    model = builder.finalize()
    return model, RigidBodySolver(model, substeps), model.state()


def run(solver, state, frames, colliders=(), gravity=G, start=0, each=None):
    """Advance ``frames`` frames; ``each(frame, state)`` after each one."""
    reports = []
    for f in range(start, start + frames):
        reports.append(solver.advance(state, RigidFrameInputs(f, f * DT, DT, gravity,
                                                              list(colliders))))
        if each is not None:
            each(f + 1, state)
    return reports
