"""Render attributes of one emitter's alive particles, ready for a cache frame."""
from __future__ import annotations

import numpy as np

from ..errors import PhysanimError
from .model import ParticleModel, ParticleState


def velocity_alignment(v: np.ndarray) -> np.ndarray:
    """Euler XYZ angles (n, 3) [rad] that turn local +Z onto the velocity direction.

    With R = Rz(0) Ry(b) Rx(a): R z = (cos a sin b, -sin a, cos a cos b), so a = -asin(d_y),
    b = atan2(d_x, d_z). A particle at rest keeps (0, 0, 0).
    """
    speed = np.linalg.norm(v, axis=1)
    d = v / np.where(speed > 1e-9, speed, np.inf)[:, None]
    out = np.zeros_like(v)
    moving = speed > 1e-9
    out[:, 0] = np.where(moving, -np.arcsin(np.clip(d[:, 1], -1.0, 1.0)), 0.0)
    out[:, 1] = np.where(moving, np.arctan2(d[:, 0], d[:, 2]), 0.0)
    return out


def emitter_arrays(model: ParticleModel, state: ParticleState, emitter: int,
                   frame: int | None = None) -> dict[str, np.ndarray]:
    """Arrays of the particles of ``emitter`` alive in ``state``.

    ``frame`` is the scene frame being written, named in error messages.

    Returns a dict of contiguous arrays: ``id`` (n,) int32, ``position`` and ``velocity`` (n, 3)
    float32 [m], [m/s], ``age`` (n,) [s], ``life`` (n,) [s], ``size`` (n,) [m] (base size times
    the size curve), ``color`` (n, 4) RGBA (color curve over the life fraction) and, with
    shape-from-velocity (``stretch`` > 0), the instance transform the renderer uses:
    ``instance_scale`` (n, 3) and ``instance_rotation`` (n, 3) Euler, aligning the instance with
    v and stretching it along v. Without them the renderer scales instances by ``size``.
    """
    settings = model.emitters[emitter]
    # one emitter: all the particles, as views (the float32 copies below are the only ones)
    sel = slice(None) if len(model.emitters) == 1 else state.particle_emitter == emitter
    ids = state.particle_id[sel]
    if len(ids) and ids[-1] > np.iinfo(np.int32).max:
        raise PhysanimError(f"particle id {int(ids[-1]):,} exceeds the cache's 32-bit id range "
                            f"({np.iinfo(np.int32).max:,}): the bake has had more than 2^31 "
                            "births — lower the rates or bake fewer frames",
                            obj=settings.name, frame=frame, kind="emitter")
    v = state.particle_v[sel]
    age = state.particle_age[sel]
    life = state.particle_life[sel]
    frac = (age if settings.size.is_constant and settings.color.is_constant else  # t unread
            np.clip(age / np.where(life > 0.0, life, np.inf), 0.0, 1.0))
    size = state.particle_size[sel] * settings.size.evaluate(frac)[:, 0]
    f32 = np.float32
    out = {
        "id": ids.astype(np.int32),
        "position": np.ascontiguousarray(state.particle_x[sel], f32),
        "velocity": np.ascontiguousarray(v, f32),
        "age": age.astype(f32),
        "life": life.astype(f32),
        "size": size.astype(f32),
        "color": settings.color.evaluate(frac, f32),
    }
    if settings.stretch > 0.0:  # round particles need no instance transform: size scales them
        scale = np.repeat(size[:, None], 3, axis=1)
        scale[:, 2] *= 1.0 + settings.stretch * np.linalg.norm(v, axis=1)
        out["instance_scale"] = np.ascontiguousarray(scale, f32)
        out["instance_rotation"] = np.ascontiguousarray(velocity_alignment(v), f32)
    return out
