"""Hit the mark: a rigid body given a Target object and a Target Frame is launched so that its
centre arrives at the target's origin at that frame.

The launch velocity (the body's Initial Velocity, which the solve writes) starts from the
closed form of a throw under gravity, v0 = (p - x0 - g T^2 / 2) / T, then is corrected on the
simulator itself: the rigid bodies are baked to the target frame (into a scratch cache, thrown
away) and v0 moves by the miss over T, until the miss is under :data:`TOLERANCE`. In free
flight the simulated motion is affine in v0 with slope T (also with damping, whose slope is
close to it), so this converges in a few bakes; a collision on the way bends the path, and is
reported with its frame.
"""
from __future__ import annotations

import bpy
import numpy as np

from ..core.controls.timing import TimeMap
from ..core.errors import PhysanimError
from . import convert, timing

TOLERANCE = 1.0e-4  # m: the miss the solve stops at (a tenth of a millimetre)
MAX_BAKES = 12


def aimed(roles) -> list:
    """The rigid bodies with a target (kinematic ones follow their animation instead)."""
    return [ob for ob in roles.rigid_bodies if ob.physanim.rigid_body.target is not None
            and not ob.physanim.rigid_body.kinematic]


def solve(context, roles, frame_start: int, frame_end: int, clock: TimeMap) -> list[str]:
    """Set each aimed body's Initial Velocity so it hits its target; returns report lines.
    ``clock``: the bake's time map (the flight lasts the simulated time to the target frame)."""
    from .bake import BakeJob

    bodies = aimed(roles)
    if not bodies:
        return []
    scene = context.scene
    dt = convert.seconds_per_frame(scene)
    gravity = np.array(convert.gravity(scene))
    goals, spans = [], []
    keep = scene.frame_current
    for ob in bodies:
        p = ob.physanim.rigid_body
        if p.target == ob:
            raise PhysanimError("a body cannot aim at itself — pick another target object",
                                obj=ob.name, frame=frame_start, kind="rigid body")
        if not frame_start < p.target_frame <= frame_end:
            raise PhysanimError(f"Target Frame {p.target_frame} is not within the bake's frames "
                                f"{frame_start + 1}-{frame_end}", obj=ob.name,
                                frame=frame_start, kind="rigid body")
        scene.frame_set(p.target_frame)
        goals.append(np.array(p.target.matrix_world.translation))
        spans.append(float(np.diff(timing.frame_seconds(clock, scene,
                                                        [frame_start, p.target_frame]))[0]))
    scene.frame_set(keep)
    goals, spans = np.array(goals), np.array(spans)
    last = max(ob.physanim.rigid_body.target_frame for ob in bodies)
    names = {ob.name for ob in roles.rigid_bodies}
    notes: list[str] = []
    hits: list[list[int]] = [[] for _ in bodies]
    slope = spans.copy()  # d(arrival)/d(launch) per body: T in free flight; secant updates
    previous = None  # (launch, arrival) of the last bake
    best = (np.inf, None, hits, None)  # (worst miss, launch, collisions, misses) of the closest
    for attempt in range(MAX_BAKES):
        job = BakeJob(context, names, aim=False, checkpoint_every=float("inf"))
        try:
            index = [job.rigid.index[ob.name] for ob in bodies]
            if attempt == 0:  # the closed form, from where each body starts
                start = job.rigid.system.state.body_x[index]
                launch = (goals - start - 0.5 * gravity * spans[:, None] ** 2) / spans[:, None]
                _set_launch(bodies, launch)
                continue
            arrived, hits = _fly(job, bodies, index, last, gravity, dt)
        finally:
            job.abort()
        miss = goals - arrived
        launch = np.array([ob.physanim.rigid_body.initial_velocity for ob in bodies])
        worst = np.linalg.norm(miss, axis=1).max()
        if worst < best[0]:
            best = (worst, launch, hits, miss)
        if worst < TOLERANCE:
            break
        if previous is not None:  # the slope the last two bakes show (damping lowers it)
            dv, dx = launch - previous[0], arrived - previous[1]
            moved = np.einsum("ij,ij->i", dv, dv)
            fitted = np.einsum("ij,ij->i", dx, dv) / np.where(moved > 0.0, moved, 1.0)
            slope = np.where((moved > 0.0) & (fitted > 0.05 * spans), fitted, slope)
        previous = (launch, arrived)
        _set_launch(bodies, launch + miss / slope[:, None])
    else:  # the closest launch found stays, and the report says by how much it misses
        _, launch, hits, miss = best
        _set_launch(bodies, launch)
        worst = int(np.argmax(np.linalg.norm(miss, axis=1)))
        notes.append(f'"{bodies[worst].name}" misses its target by '
                     f"{1000 * np.linalg.norm(miss[worst]):.1f} mm after {MAX_BAKES} tries")
    for ob, frames in zip(bodies, hits):
        if frames:
            notes.append(f'"{ob.name}" hits something on its way to "'
                         f'{ob.physanim.rigid_body.target.name}" at frame {frames[0]}')
    return notes


def _set_launch(bodies: list, launch: np.ndarray) -> None:
    for ob, velocity in zip(bodies, launch):
        ob.physanim.rigid_body.initial_velocity = tuple(float(v) for v in velocity)


def _fly(job, bodies, index, last: int, gravity, dt: float):
    """Bake to frame ``last``; each body's centre at its target frame, and the frames on the
    way where its velocity jumped (a collision): changed by more than gravity and its damping
    explain (0.05 m/s and 2 % of its speed of slack)."""
    mass = job.rigid.model.body_mass[index]
    damping = np.array([ob.physanim.rigid_body.linear_damping for ob in bodies])
    keep = np.exp(-damping * dt)[:, None]
    velocity = job.rigid.system.state.body_P[index] / mass[:, None]
    arrived = np.zeros((len(bodies), 3))
    hits: list[list[int]] = [[] for _ in bodies]
    while job.frame < last:
        job.step(bpy.context)  # one simulation frame (dt): the frames it shows, with poses
        state = job.rigid.system.state
        now = state.body_P[index] / mass[:, None]
        jump = np.linalg.norm(now - (velocity * keep + gravity * dt), axis=1)
        slack = 0.05 + 0.02 * np.linalg.norm(velocity, axis=1)
        velocity = now
        for k, ob in enumerate(bodies):
            target_frame = ob.physanim.rigid_body.target_frame
            if job.frame <= target_frame and jump[k] > slack[k]:
                hits[k].append(job.frame)
            if target_frame in job.rigid.centres:
                arrived[k] = job.rigid.centres[target_frame][index[k]]
    return arrived, hits
