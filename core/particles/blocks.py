"""Large particle states moved in blocks that fit the processor's caches.

A sub-step's passes from collide to check (:mod:`.solver`) each stream the whole state through
memory: forces, the integrator's stages, the colliders' queries and responses, the checks. At
a million particles each (n, 3) array is 24 MB and every pass reads it from main memory; a
block of 65,536 particles keeps its arrays (1.5 MB each) in the cache between the passes. When
each particle's sub-step is a function of its own values (no particle springs or rigid links,
constraints, ties, interactions or particle collisions: :func:`separable`), moving the state
block by block gives each particle the same arithmetic; only an integrator's sums over the
whole state (RK4's weighted stages are one product) may round otherwise, which is why the
adaptive RK45, whose step size an error over all particles decides, is never split.
"""
from __future__ import annotations

import numpy as np

from .rest import unchanged

BLOCK = 65_536  # particles per block
# integrators whose step treats each particle alone (RK45 picks one step size for all of them)
BLOCKED = ("EULER", "SYMPLECTIC_EULER", "MIDPOINT", "RK4")


def separable(integrator: str, alone: bool, inputs) -> bool:
    """Whether a frame interval's sub-steps move each particle on its own (``alone``: no
    particle springs, rigid links, constraints or ties; ``inputs``: its FrameInputs)."""
    return alone and integrator in BLOCKED and not inputs.interactions and not inputs.collisions


class Looked:
    """What a sub-step learns of its moved particles while their values are in the cache
    (passed to :func:`in_blocks`): which were left exactly as they were (``still``, when
    ``rest`` is the sub-step's :class:`~.rest.Conditions`; else None) and whether every one is
    finite and within ``bounds`` by its quick test (``inside``, :meth:`~..bounds.StateBounds
    .within`)."""

    def __init__(self, n: int, rest, bounds):
        self.still = None if rest is None else np.empty(n, bool)
        self.inside = True
        self._bounds = bounds

    def __call__(self, rows: slice, x0, v0, x1, v1) -> None:
        if self.still is not None:
            self.still[rows] = unchanged(x0, v0, x1, v1)
        if self.inside and len(x1):
            self.inside = self._bounds.within(x1, v1)


def in_blocks(move, step, state, s0: float, s1: float, t: float, look: Looked | None = None):
    """``move(step, state, s0, s1, t, into)`` (:meth:`.solver.ParticleSolver._move`) over the
    whole state, block by block when the interval is separable and the state spans two blocks
    or more, each block's integrator writing into the new state's rows (``into``); returns what
    ``move`` returns for the whole state (positions and velocities before, no ties).
    ``look(rows, x0, v0, x1, v1)``: called on each block (or the whole state) once moved."""
    n = state.particle_count
    if not step.blocks or n < 2 * BLOCK:
        moved = move(step, state, s0, s1, t)
        if look is not None:
            look(slice(0, n), moved[0], moved[1], state.particle_x, state.particle_v)
        return moved
    x0, v0 = state.particle_x, state.particle_v  # no pass writes into them: moves make new ones
    x1, v1 = np.empty_like(x0), np.empty_like(v0)
    report = step.report
    steps = report.integrator_steps
    for lo in range(0, n, BLOCK):
        rows = slice(lo, min(lo + BLOCK, n))
        part = state.subset(rows)  # views of the block's rows
        into = (x1[rows], v1[rows])
        move(step, part, s0, s1, t, into)
        for new, out in zip((part.particle_x, part.particle_v), into):
            if new is not out:  # (not written in place: a collision, another integrator)
                out[...] = new
        if look is not None:
            look(rows, x0[rows], v0[rows], *into)
        if lo == 0:
            steps = report.integrator_steps  # the sub-step's steps, counted once
    report.integrator_steps = steps
    state.particle_x, state.particle_v = x1, v1
    return x0, v0, ([], None)
