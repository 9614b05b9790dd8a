"""Vertices attached to other objects (:class:`~.model.Attachment`): where they are held during
a sub-step, and — when the object is a rigid body the world stepped first — how the body and
the mesh move each other (two-way coupling).

The body has already taken its frame when the mesh steps, so the mesh's step holds the attached
vertices on the body's path; then the body's velocity change du (6: linear and angular) that
the mesh's pull makes is solved *implicitly*, with the mesh's response to it: Baraff-Witkin's
step answers, to first order, how its free vertices and the holding impulses change when the
attached vertices' velocity changes by G du (G: du -> v + w x r at each attached vertex), one
solve per degree of freedom (:meth:`~.implicit.BaraffWitkin.response`). With dR those impulse
changes and r0 the holding impulses of the step,

    (M_body + G^T dR) du = -G^T r0,

the body's mass and inertia plus what the mesh adds to them (its attached mass, and the
stiffness and damping with which it resists being moved within the step): the Schur complement
of the mesh's system, so a light body on a stiff cloth is as stable as the cloth itself. The
body's own part of that linearisation joins it: turning the body by h w turns the arms r at
which it takes the holding impulses J, so their moments change by -h sum(r J^T - (J.r) 1) w — a
stiffness of about T h^2 for a rope's tension T running through a plank, without which a rope
bridge's light planks pitched ever harder and blew up within 15 frames. (Handing
the holding impulses to the body one frame late instead blew up within 30 frames: a 1 kg box
on a default cloth, the sway mode growing fourfold per frame.) The mesh's velocities take their
response to du at once; the body takes the impulses.

The impulse on a held vertex over a sub-step is the implicit step's residual there
(:meth:`~.implicit.BaraffWitkin.residual`): with the step's linearised forces f,
M dv = h f + r, and the mesh's internal forces (equal and opposite pairs, and their Jacobian
blocks) cancel in any sum over vertices, so the sum of r is the momentum change less h times
the external forces — what the held vertices took is exactly what the mesh gained from its
attachments, and the bodies get the opposite; the coupling's correction adds its own linear
change of r. The free vertices' share of r is the solve's error (an inexact conjugate-gradient
solve): it is taken out of the free vertices' velocities, evenly, so the mesh and the bodies
together conserve momentum to rounding (vertices on colliders are left alone: their share is
the collider's push, which goes back to the collider when it is a body).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import PhysanimError
from ..transforms import TransformPath, cross, inverse_affine, rotation_vector_matrix, transform_points
from ..world import Reaction
from .model import SpringMeshModel, SpringMeshState


@dataclass
class Held:
    """The attachments over one frame interval.

    Attributes:
        paths: per attachment, its target's path (None: the world).
        coupled: per attachment, the body it moves (a rigid body stepped first), or None.
        bodies: the bodies stepped first: name -> (inertia at the frame's end
            (``BodyInertia``), path over the frame) — those the mesh hangs on or rests on
            move with it.
        du: coupled body name -> (6,) velocity change the mesh gave it so far this frame
            (the attached vertices move with it in the frame's later sub-steps).
        move: coupled body name -> (6,) how far that moved the body since the last reaction
            (centre [m], rotation vector [rad]).
        shift: per attachment, (k, 3) how far that moved its vertices this frame [m].
        travel: coupled body name -> (3,) how far that moved its centre this frame [m].
    """

    paths: list
    coupled: list
    bodies: dict
    du: dict = field(default_factory=dict)
    move: dict = field(default_factory=dict)
    shift: list = field(default_factory=list)
    travel: dict = field(default_factory=dict)


def frame_paths(model: SpringMeshModel, state: SpringMeshState, colliders, targets: dict,
                bodies: dict, frame: int) -> Held:
    """Each attachment's target path over the interval, binding the vertices to it on the
    first frame, and the paths of ``bodies`` (rigid bodies stepped first, which move as
    colliders). An attachment to one of them is coupled."""
    by_name = {c.name: c for c in colliders}
    paths, coupled = [], []
    moving = {b: (bodies[b], TransformPath(c.matrix0, c.matrix1, c.matrices))
              for b, c in by_name.items() if b in bodies}
    for k, a in enumerate(model.attachments):
        if a.target is None:
            path = None
        elif a.target in by_name:
            c = by_name[a.target]
            path = TransformPath(c.matrix0, c.matrix1, c.matrices)
        elif a.target in targets:
            path = TransformPath(*targets[a.target])
        else:
            raise PhysanimError(f'the attachment target "{a.target}" has no transform this '
                                "frame — is it in the scene?", obj=model.settings.name,
                                frame=frame, kind="spring mesh")
        if state.bound[k] is None:
            x = state.x[a.index]
            state.bound[k] = x.copy() if path is None else \
                transform_points(inverse_affine(path.m0), x)
        paths.append(path)
        coupled.append(a.target if a.target in bodies else None)
    return Held(paths, coupled, moving, {b: np.zeros(6) for b in moving},
                {b: np.zeros(6) for b in moving},
                [np.zeros((len(a.index), 3)) for a in model.attachments],
                {b: np.zeros(3) for b in moving})


def hold(model: SpringMeshModel, state: SpringMeshState, held: Held, s0: float, s1: float,
         h: float, pin_x1: np.ndarray, pin_v: np.ndarray) -> None:
    """Put each attachment's targets at the sub-step's end into ``pin_x1`` and its velocity
    over the sub-step into ``pin_v`` (n, 3), in place (a coupled body's path moved on by the
    velocity the mesh gave it in earlier sub-steps)."""
    for body, du in held.du.items():
        held.move[body] += h * du
        held.travel[body] += h * du[:3]
    for k, a in enumerate(model.attachments):
        path = held.paths[k]
        if path is None:
            pin_x1[a.index], pin_v[a.index] = state.bound[k], 0.0
            continue
        p0 = transform_points(path.matrices(s0), state.bound[k])
        p1 = transform_points(path.matrices(s1), state.bound[k])
        v = (p1 - p0) / h
        body = held.coupled[k]
        if body is not None:
            extra = _point_velocity(held.du[body], p1 - _path_centre(held, body, s1))
            held.shift[k] += h * extra
            p1, v = p1 + held.shift[k], v + extra
        pin_x1[a.index], pin_v[a.index] = p1, v


def _path_centre(held: Held, body: str, s: float) -> np.ndarray:
    """The body's centre of mass at ``s`` of the frame on its own path (carried on it from
    the end), before the mesh moved it."""
    inertia, path = held.bodies[body]
    local = transform_points(inverse_affine(path.m1), inertia.centre[None])
    return transform_points(path.matrices(s), local)[0]


def _centre(held: Held, body: str, s: float) -> np.ndarray:
    """The body's centre of mass at ``s`` of the frame: on its path, moved as far as the mesh
    moved it so far (the lever arms of the vertices the mesh moved with it)."""
    return _path_centre(held, body, s) + held.travel[body]


def _point_velocity(du: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(k, 3) velocities v + w x r of points at ``r`` from the centre for du = [v, w]."""
    return du[:3] + cross(du[3:], r)


def couple(model: SpringMeshModel, held: Held, integrator, pressed: dict,
           outside: np.ndarray, x1: np.ndarray, v1: np.ndarray, h: float, s1: float) -> None:
    """The velocity changes of the bodies the mesh hangs on (attachments) or rests on
    (``pressed``: body -> (vertices held on its surface by the step, their normals)), solved
    with the mesh's response (module docstring): adds them to ``held.du``, and the mesh's
    response to ``v1``, ``x1`` and the step's impulses from outside ``outside`` (in place).
    A vertex on a surface moves with the body only along the normal, and pushes it only
    along it."""
    links: dict[str, list] = {}
    for a, b in zip(model.attachments, held.coupled):
        if b is not None:
            links.setdefault(b, []).append((a.index, np.full((len(a.index), 3), np.nan)))
    for b, (index, normal) in pressed.items():
        links.setdefault(b, []).append((index, normal))
    names = list(links)
    if not names:
        return
    columns, g_rows, arms = [], [], []
    for b in names:  # G: each body's six unit motions at its vertices
        index = np.concatenate([i for i, _ in links[b]])
        normal = np.concatenate([n for _, n in links[b]])
        r = x1[index] - _centre(held, b, s1)
        g = np.stack([_along(gj, normal) for gj in _g_transpose(r)])  # (6, k, 3)
        g_rows.append((index, g))
        arms.append(r)
        for j in range(6):
            given = np.zeros_like(v1)
            given[index] = g[j]
            columns.append(integrator.response(given))
    size = 6 * len(names)
    coupling, inertia, rhs = np.zeros((size, size)), np.zeros((size, size)), np.zeros(size)
    for p, (b, (index, g), r) in enumerate(zip(names, g_rows, arms)):
        rows = slice(6 * p, 6 * p + 6)
        rhs[rows] = -np.einsum("jkc,kc->j", g, outside[index])
        for q, (_, change) in enumerate(columns):
            coupling[rows, q] = np.einsum("jkc,kc->j", g, change[index])
        body = held.bodies[b][0]
        inertia[rows, rows] = np.block([[body.mass * np.eye(3), np.zeros((3, 3))],
                                        [np.zeros((3, 3)), body.inertia]])
        # turning the body by h w turns the arms at which the mesh holds it: the moments of the
        # impulses J it takes change by h sum((w x r) x J) = -h sum(r J^T - (J.r) 1) w
        impulse = -outside[index]
        coupling[6 * p + 3:6 * p + 6, 6 * p + 3:6 * p + 6] -= h * (
            r.T @ impulse - np.einsum("ij,ij->", r, impulse) * np.eye(3))
    du = np.linalg.solve(inertia + coupling, rhs)
    # backward Euler: the mesh and the bodies move by h times the velocity change (the bodies'
    # attached vertices with them, turned exactly as the reactions' move turns the body); the
    # impulses that hold them change linearly with it, so the bodies take exactly M du
    before = x1.copy()
    for d, (dv, d_impulse) in zip(du, columns):
        v1 += d * dv
        x1 += (h * d) * dv
        outside += d * d_impulse
    for p, b in enumerate(names):
        step = du[6 * p:6 * p + 6]
        held.du[b] += step
        held.move[b] += h * step
        centre = _centre(held, b, s1)
        held.travel[b] += h * step[:3]
        turn = rotation_vector_matrix(h * step[3:])
        for k, (a, body) in enumerate(zip(model.attachments, held.coupled)):
            if body == b:
                x1[a.index] = centre + h * step[:3] + (before[a.index] - centre) @ turn.T
                held.shift[k] += x1[a.index] - before[a.index]


def _along(u: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(k, 3) vectors u, each kept whole where its normal row is NaN (an attached vertex) and
    projected on the normal elsewhere (a vertex on a surface)."""
    whole = np.isnan(normal[:, 0])
    n = np.where(whole[:, None], 0.0, normal)
    return np.where(whole[:, None], u, np.einsum("ij,ij->i", u, n)[:, None] * n)


def _g_transpose(r: np.ndarray) -> np.ndarray:
    """(6, k, 3): G^T's rows for points at ``r`` (k, 3) from the centre — force sums for the
    linear part, moments r x f for the angular part."""
    k = len(r)
    g = np.zeros((6, k, 3))
    for j in range(3):
        g[j, :, j] = 1.0
        g[3 + j] = cross(np.eye(3)[j], r)  # (r x f)_j = f . (e_j x r)
    return g


def react(model: SpringMeshModel, held: Held | None, mass: np.ndarray, free: np.ndarray,
          touched: np.ndarray, hits: dict, outside: np.ndarray, x1: np.ndarray,
          v1: np.ndarray, h: float, s1: float) -> list[Reaction]:
    """The impulses the coupled attachments took this sub-step (ending at ``s1`` of the
    frame), and those with which bodies pushed the vertices in ``hits`` (body name ->
    vertices), as reactions on the bodies (``outside``: the step's impulses from outside the
    mesh's forces, per vertex). Each acts where it does about the body's centre now; as a
    reaction's point it is carried to the centre at the frame's end (before the move), about
    which the body takes it. The free vertices' share of them is the solve's error: it is taken
    out of their velocities (``x1``, ``v1`` in place), so the momentum balance is exact.
    ``touched``: (n,) vertices a collider pushed (their share is its push)."""
    loose = free & ~touched
    if loose.any():
        shift = outside[loose].sum(axis=0) / mass[loose].sum()
        v1[loose] -= shift
        x1[loose] -= h * shift
    if held is None:
        return []

    def at(body: str, index: np.ndarray) -> np.ndarray:
        return x1[index] - _centre(held, body, s1) + held.bodies[body][0].centre

    out = [Reaction(body, at(body, a.index), -outside[a.index])
           for a, body in zip(model.attachments, held.coupled) if body is not None]
    out.extend(Reaction(body, at(body, i), -outside[i]) for body, i in hits.items() if len(i))
    for body, move in held.move.items():
        if np.any(move):  # how far the implicit steps moved it, given once
            out.append(Reaction(body, np.zeros((0, 3)), np.zeros((0, 3)), move))
            held.move[body] = np.zeros(6)
    return out
