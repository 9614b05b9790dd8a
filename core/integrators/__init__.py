"""Time integrators that advance a flat state ``y`` of any system by one time step.

An integrator sees only the solver interface of Witkin & Baraff's notes (:class:`System`):
``dim``, ``get_state()``, ``set_state(y)`` and ``derivative(t, y)``. The state is one flat
float64 vector. Second-order systems use the convention ``y = [x, v]`` — the first ``dim / 2``
values are positions, the last ``dim / 2`` velocities — and ``derivative`` returns ``[v, a]``;
:class:`SymplecticEuler` and ``ImplicitEuler(second_order=True)`` (what ``make_integrator``
builds for ``IMPLICIT``) rely on it; every other integrator works on any first-order system.

Euler, midpoint, RK4 and the Dormand–Prince 5(4) pair are Butcher tableaux run by one generic
:func:`rk_step` (as in ``scipy.integrate._ivp.rk``). :class:`Integrator.step` does the bookkeeping
(read state, check the result is finite, write state) and subclasses implement ``_step_impl``.
Modules: :mod:`.base` (interface, report, base class), :mod:`.runge_kutta` (explicit methods),
:mod:`.implicit` (implicit Euler), :mod:`.krylov` (the matrix-free linear solvers of the implicit
steppers: BiCGSTAB, and the projected preconditioned CG the spring meshes' Baraff-Witkin
stepper, an :class:`Integrator` of :mod:`physanim.core.springs.implicit`, solves with).
No integrator holds module-level state; :class:`AdaptiveRK` remembers its last good step size on
the instance only.
"""
from __future__ import annotations

import math

from .base import Derivative, Integrator, JacobianSystem, PointSystem, StepReport, System
from .implicit import ImplicitEuler
from .krylov import bicgstab, projected_pcg
from .runge_kutta import (DOPRI5_TABLEAU, EULER_TABLEAU, MAX_ADAPTIVE_STEPS, MIDPOINT_TABLEAU,
                          RK4_TABLEAU, AdaptiveRK, ExplicitRK, SymplecticEuler, Tableau, rk_step)

__all__ = [
    "DOPRI5_TABLEAU", "EULER_TABLEAU", "INTEGRATORS", "MAX_ADAPTIVE_STEPS", "MIDPOINT_TABLEAU",
    "RK4_TABLEAU", "SPRING_INTEGRATORS", "AdaptiveRK", "Derivative", "ExplicitRK",
    "ImplicitEuler", "Integrator", "JacobianSystem", "PointSystem", "StepReport",
    "SymplecticEuler", "System", "Tableau", "bicgstab", "make_integrator", "projected_pcg",
    "rk_step",
]

INTEGRATORS = ("EULER", "SYMPLECTIC_EULER", "MIDPOINT", "RK4", "RK45", "IMPLICIT")
#: spring meshes also step with BDF2 (:mod:`physanim.core.springs.bdf2`)
SPRING_INTEGRATORS = INTEGRATORS + ("BDF2",)


def make_integrator(name: str, tolerance: float = 1e-4) -> Integrator:
    """Integrator for one of :data:`INTEGRATORS`.

    Args:
        name: identifier from :data:`INTEGRATORS`.
        tolerance: relative tolerance of ``RK45`` (absolute tolerance ``tolerance * 1e-3``, in
            state units: metres and metres per second) and of the ``IMPLICIT`` linear solve;
            ignored by the fixed-step explicit methods. ``SYMPLECTIC_EULER`` and ``IMPLICIT``
            expect the ``y = [x, v]`` convention.

    Raises:
        ValueError: unknown ``name`` or a ``tolerance`` that is not finite and > 0.
    """
    if name not in INTEGRATORS:
        raise ValueError(f"unknown integrator {name!r}; choose one of {', '.join(INTEGRATORS)}")
    if not (math.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"integrator tolerance must be finite and > 0 (got {tolerance!r})")
    if name == "RK45":
        return AdaptiveRK(DOPRI5_TABLEAU, rtol=tolerance, atol=tolerance * 1e-3)
    if name == "IMPLICIT":  # physanim systems follow the [x, v] convention
        return ImplicitEuler(rtol=tolerance, second_order=True)
    if name == "SYMPLECTIC_EULER":
        return SymplecticEuler()
    tableau = {"EULER": EULER_TABLEAU, "MIDPOINT": MIDPOINT_TABLEAU, "RK4": RK4_TABLEAU}[name]
    return ExplicitRK(tableau)
