"""Hit the mark: a rigid body, or a particle emitter's burst, given a Target object and a Target
Frame is launched so that its centre (a burst's: the mean of its particles) arrives at the
target's origin at that frame.

The launch (a body's Initial Velocity, an emitter's Launch Velocity, which the solve writes)
starts from the closed form of a throw under gravity, v0 = (p - x0 - g T^2 / 2) / T, then is
corrected on the simulator itself: the scene is baked to the target frame (into scratch caches,
thrown away) and v0 moves by the miss over the slope, until the miss is under
:data:`TOLERANCE`. In free flight the simulated motion is affine in v0 with slope T (also with
drag, whose slope is close to it: the last two bakes measure it), so this converges in a few
bakes; a collision on the way bends the path, and is reported with its frame. T is simulated
time (the Time Scale counts).
"""
from __future__ import annotations

import bpy
import numpy as np

from ..core.controls.timing import TimeMap
from ..core.errors import PhysanimError
from . import convert, timing

TOLERANCE = 1.0e-4  # m: the miss the solve stops at (a tenth of a millimetre)
MAX_BAKES = 12
# a velocity jump beyond gravity and drag that counts as a collision: slack [m/s] + fraction
JUMP_SLACK, JUMP_FRACTION = 0.05, 0.02


def aimed(roles) -> list:
    """The rigid bodies with a target (kinematic ones follow their animation instead)."""
    return [ob for ob in roles.rigid_bodies if ob.physanim.rigid_body.target is not None
            and not ob.physanim.rigid_body.kinematic]


def aimed_emitters(roles) -> list:
    """The emitters with a target."""
    return [ob for ob in roles.emitters if ob.physanim.emitter.target is not None]


def solve(context, roles, frame_start: int, frame_end: int, clock: TimeMap) -> list[str]:
    """Set each aimed body's Initial Velocity and each aimed emitter's Launch Velocity so they
    hit their targets; returns report lines. ``clock``: the bake's time map."""
    notes = []
    bodies = aimed(roles)
    if bodies:
        notes += _solve(context, _Bodies(context.scene, roles, bodies, frame_start, frame_end,
                                         clock))
    emitters = aimed_emitters(roles)
    if emitters:
        notes += _solve(context, _Bursts(context.scene, roles, emitters, frame_start, frame_end,
                                         clock))
    return notes


class _Aim:
    """What the solve needs of the things it aims: their goals and flight times, their launch
    (read and write), a first guess and a scratch flight."""

    kind = ""

    def __init__(self, scene, roles, objects: list, frame_start: int, frame_end: int,
                 clock: TimeMap):
        self.scene, self.objects, self.clock = scene, objects, clock
        self.gravity = np.array(convert.gravity(scene))
        self.names = {ob.name for ob in roles.rigid_bodies} | {ob.name for ob in objects}
        goals, self.spans = [], []
        keep = scene.frame_current
        for ob in objects:
            p = self.props(ob)
            if p.target == ob:
                raise PhysanimError("it cannot aim at itself — pick another target object",
                                    obj=ob.name, frame=frame_start, kind=self.kind)
            if not frame_start < p.target_frame <= frame_end:
                raise PhysanimError(f"Target Frame {p.target_frame} is not within the bake's "
                                    f"frames {frame_start + 1}-{frame_end}", obj=ob.name,
                                    frame=frame_start, kind=self.kind)
            self.check(ob, frame_start)
            scene.frame_set(p.target_frame)
            goals.append(np.array(p.target.matrix_world.translation))
            self.spans.append(float(timing.frame_seconds(clock, scene, p.target_frame)
                                    - self.launch_time(ob)))
        scene.frame_set(keep)
        self.goals, self.spans = np.array(goals), np.array(self.spans)
        self.last = max(self.props(ob).target_frame for ob in objects)

    def props(self, ob):
        raise NotImplementedError

    def check(self, ob, frame_start: int) -> None:
        """Refuse what cannot be aimed (before anything is baked)."""

    def launch_time(self, ob) -> float:
        """Simulated time [s] the launch happens at."""
        raise NotImplementedError

    def launch(self) -> np.ndarray:
        return np.array([tuple(getattr(self.props(ob), self.launch_key))
                         for ob in self.objects])

    def set_launch(self, launch: np.ndarray) -> None:
        if not np.isfinite(launch).all():  # never written into the scene
            k = int(np.argmax(~np.isfinite(launch).all(axis=1)))
            raise PhysanimError(f"the launch solve came to {launch[k].tolist()} m/s",
                                obj=self.objects[k].name, kind=self.kind)
        for ob, velocity in zip(self.objects, launch):
            setattr(self.props(ob), self.launch_key, tuple(float(v) for v in velocity))

    def guess(self, job) -> np.ndarray:
        raise NotImplementedError

    def fly(self, job) -> tuple[np.ndarray, list[list[int]]]:
        raise NotImplementedError

    def close_form(self, start: np.ndarray, own: np.ndarray) -> np.ndarray:
        """v0 = (p - x0 - g T^2 / 2) / T, less the velocity the thing has of its own."""
        t = self.spans[:, None]
        return (self.goals - start - 0.5 * self.gravity * t ** 2) / t - own


class _Bodies(_Aim):
    kind = "rigid body"
    launch_key = "initial_velocity"

    def props(self, ob):
        return ob.physanim.rigid_body

    def launch_time(self, ob) -> float:
        return float(timing.frame_seconds(self.clock, self.scene, self._start))

    def __init__(self, scene, roles, objects, frame_start, frame_end, clock):
        self._start = frame_start
        super().__init__(scene, roles, objects, frame_start, frame_end, clock)

    def guess(self, job) -> np.ndarray:
        index = [job.rigid.index[ob.name] for ob in self.objects]
        return self.close_form(job.rigid.system.state.body_x[index], 0.0)

    def fly(self, job):
        """Bake to the last target frame; each body's centre at its target frame, and the
        frames on the way where its velocity jumped (a collision): changed by more than
        gravity and its damping explain."""
        bodies = self.objects
        index = [job.rigid.index[ob.name] for ob in bodies]
        mass = job.rigid.model.body_mass[index]
        dt = convert.seconds_per_frame(self.scene)  # one simulation frame per step
        damping = np.array([ob.physanim.rigid_body.linear_damping for ob in bodies])
        keep = np.exp(-damping * dt)[:, None]
        velocity = job.rigid.system.state.body_P[index] / mass[:, None]
        arrived = np.zeros((len(bodies), 3))
        hits: list[list[int]] = [[] for _ in bodies]
        while job.frame < self.last:
            job.step(bpy.context)
            state = job.rigid.system.state
            now = state.body_P[index] / mass[:, None]
            jump = np.linalg.norm(now - (velocity * keep + self.gravity * dt), axis=1)
            slack = JUMP_SLACK + JUMP_FRACTION * np.linalg.norm(velocity, axis=1)
            velocity = now
            for k, ob in enumerate(bodies):
                target_frame = ob.physanim.rigid_body.target_frame
                if job.frame <= target_frame and jump[k] > slack[k]:
                    hits[k].append(job.frame)
                if target_frame in job.rigid.centres:
                    arrived[k] = job.rigid.centres[target_frame][index[k]]
        return arrived, hits


class _Bursts(_Aim):
    """Emitters: the centre of a burst is the mean of its first simulation frame's births (a
    one-frame burst: all of them), alive at the target frame. A longer window is a stream:
    from a still emitter every later particle follows the same path, a frame later."""

    kind = "emitter"
    launch_key = "launch_velocity"

    def props(self, ob):
        return ob.physanim.emitter

    def check(self, ob, frame_start: int) -> None:
        p = ob.physanim.emitter
        if p.source == 'DEATHS':
            raise PhysanimError("a sub-emitter's births follow its parent's deaths: aim the "
                                "parent emitter instead", obj=ob.name, frame=frame_start,
                                kind="emitter")
        if p.frame_start < frame_start:
            raise PhysanimError(f"its births start at frame {p.frame_start}, before the bake's "
                                f"first frame {frame_start}: Hit the Mark aims births it bakes "
                                "from their start", obj=ob.name, frame=frame_start,
                                kind="emitter")
        if p.frame_start >= p.target_frame:
            raise PhysanimError(f"its births start at frame {p.frame_start}, not before Target "
                                f"Frame {p.target_frame}", obj=ob.name, frame=frame_start,
                                kind="emitter")

    def launch_time(self, ob) -> float:
        """The middle of the first births' interval (those of frame f happen during f - 1 ->
        f)."""
        tau = self.clock.tau(ob.physanim.emitter.frame_start)
        return float((tau - 0.5) * convert.seconds_per_frame(self.scene))

    def guess(self, job) -> np.ndarray:
        starts, own = [], []
        keep = self.scene.frame_current
        for ob in self.objects:
            p = ob.physanim.emitter
            self.scene.frame_set(p.frame_start)
            m = np.array(ob.matrix_world)
            starts.append(m[:3, 3])
            axis = m[:3, :3] @ np.array(convert.AXES[p.axis])
            norm = np.linalg.norm(axis)
            along = (p.source == 'ORIGIN' and p.direction == 'NORMAL') or p.direction == 'AXIS'
            own.append(p.speed * axis / norm if along and norm > 0.0 else np.zeros(3))
        self.scene.frame_set(keep)
        return self.close_form(np.array(starts), np.array(own))

    def fly(self, job):
        """Bake to the last target frame; each burst's centre at its target frame, and the
        first frame where one of its particles' velocity jumped beyond gravity (and drag)."""
        particles = job.particles
        particles.watch = {ob.name for ob in self.objects}
        arrived = np.zeros((len(self.objects), 3))
        hits: list[list[int]] = [[] for _ in self.objects]
        seen = {}  # emitter -> (time, ids, velocities, (ids, accelerations)) of the frame before
        index = {ob.name: k for k, ob in enumerate(self.objects)}
        while job.frame < self.last:
            job.step(bpy.context)
            for (name, frame), (ids, x, v, age) in sorted(particles.watched.items(),
                                                          key=lambda kv: kv[0][1]):
                k = index[name]
                target_frame = self.objects[k].physanim.emitter.target_frame
                if frame == target_frame:
                    if not len(ids):
                        raise PhysanimError(
                            f"no particle of its burst is alive at Target Frame {frame} — "
                            "raise Lifetime or bring Target Frame closer", obj=name,
                            frame=frame, kind="emitter")
                    # born in the first simulation frame with births: the one ending at or
                    # after the window's start (simulation frames end on whole simulated times)
                    born_by = np.ceil(self.clock.tau(self.objects[k].physanim.emitter.frame_start)
                                      - 1e-9)
                    first = age >= self.clock.tau(frame) - born_by - 1e-4
                    if not first.any():
                        raise PhysanimError(
                            f"the particles of its first births have died by Target Frame "
                            f"{frame} — raise Lifetime or bring Target Frame closer",
                            obj=name, frame=frame, kind="emitter")
                    arrived[k] = x[first].mean(axis=0)
                t = float(timing.frame_seconds(self.clock, self.scene, frame))
                accel = (ids[:0], np.zeros((0, 3)))
                if name in seen:
                    t0, ids0, v0, (a_ids, a0) = seen[name]
                    common, i0, i1 = np.intersect1d(ids0, ids, return_indices=True)
                    accel = (common, (v[i1] - v0[i0]) / (t - t0))
                    # a collision is a jump in acceleration: gravity, drag and wind change
                    # it smoothly from frame to frame
                    _, j0, j1 = np.intersect1d(a_ids, common, return_indices=True)
                    jump = np.linalg.norm(accel[1][j1] - a0[j0], axis=1) * (t - t0)
                    slack = JUMP_SLACK + JUMP_FRACTION * np.linalg.norm(v[i1][j1], axis=1)
                    if frame <= target_frame and not hits[k] and (jump > slack).any():
                        hits[k].append(frame)
                seen[name] = (t, ids, v, accel)
            particles.watched.clear()
        return arrived, hits


def _solve(context, aim: _Aim) -> list[str]:
    """The secant iteration of the module docstring over scratch bakes; report lines."""
    from .bake import BakeJob

    notes: list[str] = []
    hits: list[list[int]] = [[] for _ in aim.objects]
    slope = aim.spans.copy()  # d(arrival)/d(launch) per object: T in free flight
    previous = None  # (launch, arrival) of the last bake
    best = (np.inf, None, hits, None)  # (worst miss, launch, collisions, misses) of the closest
    for attempt in range(MAX_BAKES):
        job = BakeJob(context, aim.names, aim=False, checkpoint_every=float("inf"))
        try:
            if attempt == 0:  # the closed form, from where each starts
                aim.set_launch(aim.guess(job))
                continue
            arrived, hits = aim.fly(job)
        finally:
            job.abort()
        miss = aim.goals - arrived
        launch = aim.launch()
        worst = np.linalg.norm(miss, axis=1).max()
        if worst < best[0]:
            best = (worst, launch, hits, miss)
        if worst < TOLERANCE:
            break
        if previous is not None:  # the slope the last two bakes show (drag lowers it)
            dv, dx = launch - previous[0], arrived - previous[1]
            moved = np.einsum("ij,ij->i", dv, dv)
            fitted = np.einsum("ij,ij->i", dx, dv) / np.where(moved > 0.0, moved, 1.0)
            slope = np.where((moved > 0.0) & (fitted > 0.05 * aim.spans), fitted, slope)
        previous = (launch, arrived)
        aim.set_launch(launch + miss / slope[:, None])
    else:  # the closest launch found stays, and the report says by how much it misses
        _, launch, hits, miss = best
        aim.set_launch(launch)
        worst = int(np.argmax(np.linalg.norm(miss, axis=1)))
        notes.append(f'"{aim.objects[worst].name}" misses its target by '
                     f"{1000 * np.linalg.norm(miss[worst]):.1f} mm after {MAX_BAKES} tries")
    for ob, frames in zip(aim.objects, hits):
        if frames:
            notes.append(f'"{ob.name}" hits something on its way to "'
                         f'{aim.props(ob).target.name}" at frame {frames[0]}')
    return notes
