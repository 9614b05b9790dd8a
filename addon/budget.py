"""Will a bake fit? Upper bounds of its particle count, memory and cache size, checked before
anything is simulated; a bake that would not fit fails with the estimate in the message."""
from __future__ import annotations

import math
import os
import shutil

from ..core.errors import PhysanimError
from ..core.integrators import make_integrator
from .cache_paths import cache_root
from .roles import Roles, emitter_chain

BYTES_PER_PARTICLE_FRAME = 4 * (1 + 3 + 3 + 1 + 1 + 1 + 4 + 3 + 3)  # cache arrays of output.py
BYTES_PER_PARTICLE_STATE = 8 * 16  # float64 state + integrator stages, per particle
MEMORY_BUDGET = 16 * 2**30  # the bake refuses to start when its estimate exceeds this


def estimate(scene, roles: Roles, speed: float = 1.0) -> tuple[float, float]:
    """Peak alive particles and cache bytes of a bake, from rates and lifetimes (upper bounds).
    ``speed``: the largest Time Scale of the bake (a rate is per simulated frame: at double
    speed a frame holds two frames' births)."""
    return _totals(emitter_estimates(scene, roles, speed))


def _totals(each: dict[str, tuple[float, float]]) -> tuple[float, float]:
    return sum(peak for peak, _ in each.values()), sum(size for _, size in each.values())


def emitter_estimates(scene, roles: Roles, speed: float = 1.0) -> dict[str, tuple[float, float]]:
    """:func:`estimate` of each emitter: its name -> (peak alive particles, cache bytes).

    A sub-emitter bursts its rate (+ random) where each of its parent's particles dies: at most
    every parent birth dies within the bake, so its births per frame are its parent's times that.
    """
    s = scene.physanim
    frames = math.ceil((max(0, s.frame_end - s.frame_start) + 1) * max(1.0, speed))
    baked = {ob.name for ob in roles.emitters}
    out = {}
    for ob in roles.emitters:
        chain = emitter_chain(ob)
        top = chain[-1].physanim.emitter
        if top.source == 'DEATHS' or any(o.name not in baked for o in chain):
            out[ob.name] = (0.0, 0.0)  # a chain without a mesh/origin emitter on top never emits
            continue
        p = ob.physanim.emitter
        life = p.lifetime + p.lifetime_random
        if len(chain) == 1:
            active = max(0, min(p.frame_end, s.frame_end) - max(p.frame_start, s.frame_start) + 1)
            active = math.ceil(active * max(1.0, speed))
            peak = (p.rate + p.rate_random) * min(life, active) if active else 0.0
            size = (p.rate + p.rate_random) * active * min(life, frames) * BYTES_PER_PARTICLE_FRAME
        else:
            births = math.prod(o.physanim.emitter.rate + o.physanim.emitter.rate_random
                               for o in reversed(chain))
            peak = births * min(life, frames)
            size = births * frames * min(life, frames) * BYTES_PER_PARTICLE_FRAME
        out[ob.name] = (peak, size)
    return out


def check_budget(scene, roles: Roles, speed: float = 1.0) -> dict[str, tuple[float, float]]:
    """Fail naming the scene when the estimated memory or cache size does not fit; returns
    the estimates by emitter (:func:`emitter_estimates`)."""
    each = emitter_estimates(scene, roles, speed)
    peak, cache_bytes = _totals(each)
    stages = make_integrator(scene.physanim.integrator, scene.physanim.tolerance).stages
    memory = peak * BYTES_PER_PARTICLE_STATE * (1 + stages)
    if memory > MEMORY_BUDGET:
        raise PhysanimError(
            f"an estimated {peak:,.0f} particles alive at once need about "
            f"{memory / 2**30:.1f} GiB of memory (limit {MEMORY_BUDGET / 2**30:.0f} GiB) — "
            "lower rates or lifetimes", obj=scene.name, kind="scene")
    root = cache_root(scene)
    probe = root
    while not os.path.exists(probe) and os.path.dirname(probe) != probe:
        probe = os.path.dirname(probe)
    free = shutil.disk_usage(probe).free
    if cache_bytes > free:
        raise PhysanimError(
            f"the cache needs an estimated {cache_bytes / 2**30:.2f} GiB but only "
            f"{free / 2**30:.2f} GiB are free at \"{root}\" — free space or lower rates",
            obj=scene.name, kind="scene")
    return each
