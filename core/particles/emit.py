"""Births of one emitter over one frame interval: count, sub-frame times, positions, velocities.

The count follows the seed exactly: births = rate + Rand()*rate_random with Rand uniform in
[-1, 1], rounded stochastically so the expected count is exact. Each birth has a uniform sub-frame
time u in [0, 1) and is placed by the emitter's transform (and deformed mesh) interpolated to u,
so a fast-moving emitter leaves a continuous trail rather than puffs. The emitter's own velocity
at the birth point, times ``inherit_velocity``, is added (the robot-arm throw).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..transforms import TransformPath, inverse3, norm_rows, transform_vectors
from . import sources
from .settings import EmitterFrame, EmitterSettings


@dataclass
class Births:
    """Particles born in one interval, sorted by sub-frame time ``u`` (n,) in [0, 1)."""

    u: np.ndarray
    x: np.ndarray  # (n, 3) [m] position at birth
    v: np.ndarray  # (n, 3) [m/s] velocity at birth
    life: np.ndarray  # (n,) [s]
    mass: np.ndarray  # (n,) [kg]
    size: np.ndarray  # (n,) [m]

    @classmethod
    def empty(cls) -> Births:
        z = np.zeros(0)
        return cls(z, np.zeros((0, 3)), np.zeros((0, 3)), z, z, z)

    def __len__(self) -> int:
        return len(self.u)

    def take(self, mask: np.ndarray) -> Births:
        return Births(self.u[mask], self.x[mask], self.v[mask], self.life[mask],
                      self.mass[mask], self.size[mask])


def birth_count(rng: np.random.Generator, rate: float, rate_random: float, n: int = 1) -> np.ndarray:
    """Births for ``n`` independent events: rate + U(-1, 1)*rate_random, stochastically rounded."""
    mean = rate + rng.uniform(-1.0, 1.0, size=n) * rate_random
    mean = np.maximum(mean, 0.0)  # a negative draw means "no births", as in the seed
    base = np.floor(mean)
    return (base + (rng.random(n) < mean - base)).astype(np.int64)


def _randomised(rng, count, value, spread):
    return value + rng.uniform(-1.0, 1.0, size=count) * spread


def _finish(rng, settings, frame, u, x, v_dir, v_emitter) -> Births:
    count = len(u)
    speed = _randomised(rng, count, frame.speed, frame.speed_random)
    v = v_dir * speed[:, None] + frame.inherit_velocity * v_emitter + np.asarray(frame.launch)
    life = _randomised(rng, count, frame.lifetime, frame.lifetime_random)
    size = _randomised(rng, count, frame.size, frame.size_random)
    return Births(u, x, v, life, np.full(count, frame.mass), size)


def sample_births(rng: np.random.Generator, settings: EmitterSettings, frame: EmitterFrame,
                  frame_dt: float) -> Births:
    """Births of a mesh/origin emitter over one frame interval of ``frame_dt`` seconds."""
    if not frame.active:
        return Births.empty()
    count = int(birth_count(rng, frame.rate, frame.rate_random)[0])
    if count == 0:
        return Births.empty()
    u = np.sort(rng.random(count))  # drawn also when even: the other draws stay the same
    if settings.even:
        u = (np.arange(count) + 0.5) / count
    path = TransformPath(frame.matrix0, frame.matrix1, frame.matrices)
    local_vel = None
    if settings.source == "ORIGIN":
        local = np.zeros((count, 3))
        normal_local = np.broadcast_to(np.asarray(settings.axis, float), (count, 3))
    else:
        v0 = np.asarray(frame.verts0, dtype=np.float64)
        v1 = v0 if frame.verts1 is None else np.asarray(frame.verts1, dtype=np.float64)
        tris = settings.triangles
        if settings.source == "VERTS":
            idx = sources.sample_vertices(rng, count, len(v0))
            a, b = v0[idx], v1[idx]
            normal_local = sources.vertex_normals(v0, tris)[idx] if len(tris) else \
                np.broadcast_to(np.asarray(settings.axis, float), (count, 3))
        elif settings.source == "FACES":
            tri, bary = sources.sample_faces(rng, count, v0, tris)
            corners = tris[tri]
            a = np.einsum("nk,nki->ni", bary, v0[corners])
            b = np.einsum("nk,nki->ni", bary, v1[corners])
            normal_local = sources.triangle_areas_normals(v0, tris[tri])[1]
        else:  # VOLUME
            a = sources.sample_volume(rng, count, v0, tris)
            b = a  # interior points ride with the object's transform
            normal_local = np.broadcast_to(np.asarray(settings.axis, float), (count, 3))
        local = a + u[:, None] * (b - a)
        if v1 is not v0:
            local_vel = (b - a) / frame_dt
    x = path.points(local, u)
    v_emitter = path.point_velocities(local, u, frame_dt, local_velocity=local_vel)
    axis_dir = normal_local if settings.direction == "NORMAL" else \
        np.broadcast_to(np.asarray(settings.axis, float), (count, 3))
    if settings.direction == "RANDOM":
        base = sources.random_directions(rng, count)
    else:
        lin = path.m0[:3, :3] if path.static else path.matrices(u)[:, :3, :3]
        base = transform_vectors(np.swapaxes(inverse3(lin), -1, -2), axis_dir)  # inverse-transpose
        base /= norm_rows(base)[:, None]
    direction = sources.cone_directions(rng, base, frame.spread) if frame.spread > 0 else base
    return _finish(rng, settings, frame, u, x, direction, v_emitter)


def sample_bursts(rng: np.random.Generator, settings: EmitterSettings, frame: EmitterFrame,
                  death_x: np.ndarray, death_v: np.ndarray) -> Births:
    """Sub-emitter births where parent particles died (positions/velocities (k, 3))."""
    if not frame.active or len(death_x) == 0:
        return Births.empty()
    per = birth_count(rng, frame.rate, frame.rate_random, len(death_x))
    total = int(per.sum())
    if total == 0:
        return Births.empty()
    src = np.repeat(np.arange(len(death_x)), per)
    x = death_x[src]
    pv = death_v[src]
    if settings.direction == "RANDOM":
        base = sources.random_directions(rng, total)
    elif settings.direction == "NORMAL":
        speed = np.linalg.norm(pv, axis=1, keepdims=True)
        base = np.where(speed > 1e-12, pv / np.where(speed > 1e-12, speed, 1.0), [0.0, 0.0, 1.0])
    else:
        lin = np.asarray(frame.matrix0)[:3, :3]
        axis = lin @ np.asarray(settings.axis, float)
        base = np.broadcast_to(axis / np.linalg.norm(axis), (total, 3))
    direction = sources.cone_directions(rng, base, frame.spread) if frame.spread > 0 else base
    return _finish(rng, settings, frame, np.zeros(total), x, direction, pv)
