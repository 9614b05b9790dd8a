"""Particle Model (frozen, built once) and State (everything that changes during a bake)."""
from __future__ import annotations

import zlib
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import PhysanimError
from .settings import EmitterSettings
from .sources import open_edge_count


@dataclass(frozen=True)
class ParticleModel:
    """Read-only description of a particle simulation: its emitters and seed.

    ``emit_order``: emitter indices in the order they emit within a sub-step — mesh/origin
    emitters first, then sub-emitters by depth (parents before children), so every emitter's
    deaths of a sub-step are known before its sub-emitters burst.
    """

    emitters: tuple[EmitterSettings, ...]
    seed: int = 0
    emit_order: tuple[int, ...] = ()

    @property
    def emitter_count(self) -> int:
        return len(self.emitters)

    def state(self, t: float = 0.0) -> ParticleState:
        """A fresh State at time ``t`` [s]: no particles, one random generator per emitter.

        Each generator is seeded from (scene seed, emitter seed, CRC-32 of the emitter's UTF-8
        name) — never from the emitter's index — so adding, removing, reordering or renaming
        *other* emitters leaves this emitter's particles bit-identical. Renaming the emitter
        itself reseeds it. (Blender object names are unique, so two emitters never share a name.)
        """
        rngs = [np.random.default_rng([int(self.seed) & 0xFFFFFFFF, int(e.seed) & 0xFFFFFFFF,
                                       emitter_name_hash(e.name)])
                for e in self.emitters]
        return ParticleState.empty(t, rngs)


def emitter_name_hash(name: str) -> int:
    """A stable 32-bit hash of an emitter's name (CRC-32 of UTF-8), the same in every process.

    Python's ``hash()`` of a str is salted per process, so it cannot seed a reproducible bake.
    """
    return zlib.crc32(name.encode("utf-8")) & 0xFFFFFFFF


class ParticleModelBuilder:
    """Collects emitters; :meth:`finalize` checks them and freezes the Model.

    Args:
        seed: the scene seed; each emitter's generator derives from (scene seed, emitter seed,
            hash of the emitter's name), so adding, removing or reordering emitters never
            changes another one's particles (see :meth:`ParticleModel.state`).
    """

    def __init__(self, seed: int = 0):
        self.seed = int(seed)
        self._emitters: list[EmitterSettings] = []

    def add_emitter(self, settings: EmitterSettings) -> int:
        """Add an emitter and return its index."""
        self._emitters.append(settings)
        return len(self._emitters) - 1

    def finalize(self, frame: int | None = None) -> ParticleModel:
        """Validate emitter sources and return the frozen Model.

        Args:
            frame: scene frame named in error messages (the bake's start frame).
        """
        for e in self._emitters:
            self._check_source(e, frame)
        depth = [self._depth(i, frame) for i in range(len(self._emitters))]
        order = sorted(range(len(self._emitters)), key=lambda i: (depth[i], i))
        return ParticleModel(tuple(self._emitters), self.seed, tuple(order))

    def _depth(self, i: int, frame: int | None) -> int:
        """How many sub-emitter parents emitter ``i`` has above it (the one walk up the chain:
        a cycle is an error naming the emitter)."""
        e, seen = self._emitters[i], {i}
        d = 0
        while e.source == "DEATHS":
            if e.parent in seen:
                raise PhysanimError("sub-emitters form a cycle (an emitter is its own ancestor)",
                                    obj=self._emitters[i].name, frame=frame, kind="emitter")
            seen.add(e.parent)
            e, d = self._emitters[e.parent], d + 1
        return d

    def _check_source(self, e: EmitterSettings, frame: int | None) -> None:
        def fail(msg: str):
            raise PhysanimError(msg, obj=e.name, frame=frame, kind="emitter")

        if e.source == "VERTS" and e.vertex_count == 0:
            fail("source is VERTS but the mesh has no vertices — add geometry or emit from the origin")
        if e.source in ("FACES", "VOLUME") and len(e.triangles) == 0:
            fail(f"source is {e.source} but the mesh has no faces "
                 f"({e.vertex_count} vertices, 0 faces) — use VERTS or ORIGIN, or add faces")
        if e.source == "VOLUME":
            open_edges = open_edge_count(e.triangles)
            if open_edges:
                fail(f"source is VOLUME but the mesh is not closed ({open_edges} open or "
                     "non-manifold edges) — close the mesh or emit from FACES")
        if e.source == "DEATHS" and not 0 <= e.parent < len(self._emitters):
            fail(f"parent emitter index {e.parent} does not exist")


@dataclass
class ParticleState:
    """All particles alive at time ``t``, structure of arrays, ordered by ascending id.

    Attributes:
        particle_x: (n, 3) position [m]. particle_v: (n, 3) velocity [m/s].
        particle_mass: (n,) [kg]. particle_age: (n,) [s]. particle_life: (n,) life span [s].
        particle_size: (n,) base size [m]. particle_id: (n,) unique ids, never reused.
        particle_emitter: (n,) index of the emitter that gave birth.
        link_a, link_b: (k,) ids of particles joined by a spring; link_rest: (k,) [m];
        link_emitter: (k,) emitter whose spring settings apply.
        next_id: the id the next birth gets. last_born: per emitter, id of its latest birth.
        rngs: per emitter random generators (their state is part of the simulation state).
        pair_warm: particle-collision impulses kept from sub-step to sub-step.
        ties: per TIE constraint (its name), the particles it holds: (ids, positions in its
            target's frame, which frame) (:mod:`.ties`).
    """

    t: float
    particle_x: np.ndarray
    particle_v: np.ndarray
    particle_mass: np.ndarray
    particle_age: np.ndarray
    particle_life: np.ndarray
    particle_size: np.ndarray
    particle_id: np.ndarray
    particle_emitter: np.ndarray
    link_a: np.ndarray
    link_b: np.ndarray
    link_rest: np.ndarray
    link_emitter: np.ndarray
    next_id: int
    last_born: list[int]
    rngs: list[np.random.Generator] = field(repr=False)
    #: per particle-collision setting (its name): the pairs in contact after the last sub-step
    #: (keys from the pair's ids) and their normal impulses, which warm-start the next one
    pair_warm: dict = field(default_factory=dict, repr=False)
    ties: dict = field(default_factory=dict, repr=False)

    def __setstate__(self, saved: dict) -> None:
        """A checkpoint from before a field was added gets its default."""
        self.__dict__.update({"pair_warm": {}, "ties": {}, **saved})

    @classmethod
    def empty(cls, t: float, rngs: list[np.random.Generator]) -> ParticleState:
        f = np.zeros(0)
        i = np.zeros(0, np.int64)
        return cls(t, np.zeros((0, 3)), np.zeros((0, 3)), f, f, f, f, i, np.zeros(0, np.int32),
                   i, i, f, np.zeros(0, np.int32), 0, [-1] * len(rngs), rngs)

    @property
    def particle_count(self) -> int:
        return len(self.particle_id)

    _PER_PARTICLE = ("particle_x", "particle_v", "particle_mass", "particle_age", "particle_life",
                     "particle_size", "particle_id", "particle_emitter")

    def keep(self, mask: np.ndarray) -> None:
        """Drop particles where ``mask`` is False, and springs attached to them."""
        for name in self._PER_PARTICLE:
            setattr(self, name, getattr(self, name)[mask])
        if len(self.link_a):
            alive = np.isin(self.link_a, self.particle_id) & np.isin(self.link_b, self.particle_id)
            for name in ("link_a", "link_b", "link_rest", "link_emitter"):
                setattr(self, name, getattr(self, name)[alive])

    def subset(self, rows: np.ndarray) -> ParticleState:
        """The particles at ``rows`` as a state of their own (copies of their values; the
        random generators, springs and the rest shared)."""
        return replace(self, **{name: getattr(self, name)[rows] for name in self._PER_PARTICLE})

    def append(self, emitter: int, x, v, mass, age, life, size) -> np.ndarray:
        """Add particles born by ``emitter``; returns their new ids."""
        count = len(x)
        ids = np.arange(self.next_id, self.next_id + count, dtype=np.int64)
        self.next_id += count
        self.particle_x = np.concatenate([self.particle_x, x])
        self.particle_v = np.concatenate([self.particle_v, v])
        self.particle_mass = np.concatenate([self.particle_mass, mass])
        self.particle_age = np.concatenate([self.particle_age, age])
        self.particle_life = np.concatenate([self.particle_life, life])
        self.particle_size = np.concatenate([self.particle_size, size])
        self.particle_id = np.concatenate([self.particle_id, ids])
        self.particle_emitter = np.concatenate(
            [self.particle_emitter, np.full(count, emitter, np.int32)])
        if count:
            self.last_born[emitter] = int(ids[-1])
        return ids

    def add_links(self, a: np.ndarray, b: np.ndarray, rest: np.ndarray, emitter: int) -> None:
        self.link_a = np.concatenate([self.link_a, a])
        self.link_b = np.concatenate([self.link_b, b])
        self.link_rest = np.concatenate([self.link_rest, rest])
        self.link_emitter = np.concatenate(
            [self.link_emitter, np.full(len(a), emitter, np.int32)])

    def index_of(self, ids: np.ndarray) -> np.ndarray:
        """Array positions of particle ids (ids are sorted ascending, so a binary search)."""
        return np.searchsorted(self.particle_id, ids)

    def pose(self) -> ParticleState:
        """A copy of the particles as they are now, for drawing (see :meth:`between`); the
        random generators and springs are shared, not copied."""
        return replace(self, **{name: getattr(self, name).copy() for name in self._PER_PARTICLE})

    @classmethod
    def between(cls, a: ParticleState, b: ParticleState, w: float) -> ParticleState:
        """The particles at the fraction ``w`` of one sub-step from pose ``a`` to pose ``b``
        (time a.t + w (b.t - a.t)), for drawing an instant between sub-steps (slow motion).

        Particles in both move on the straight line between (the path a sub-step takes);
        those born during it appear once their birth time has passed, back along their
        velocity; those that died during it show until their life span ends.
        """
        if w >= 1.0:
            return b
        t = a.t + w * (b.t - a.t)
        where = np.minimum(np.searchsorted(a.particle_id, b.particle_id), max(a.particle_count - 1, 0))
        both = (a.particle_id[where] == b.particle_id) if a.particle_count else \
            np.zeros(b.particle_count, bool)
        ia = where[both]
        born = b.t - b.particle_age
        newborn = ~both & (born <= t)
        gone = ~np.isin(a.particle_id, b.particle_id)
        gone &= a.particle_age + (t - a.t) < a.particle_life
        out = {}
        for name in cls._PER_PARTICLE:
            va, vb = getattr(a, name), getattr(b, name)
            mid = vb[both].copy()
            if name in ("particle_x", "particle_v", "particle_age"):
                mid = va[ia] + w * (vb[both] - va[ia])
            young = vb[newborn]
            if name == "particle_x":
                young = vb[newborn] - (b.t - t) * b.particle_v[newborn]
            elif name == "particle_age":
                young = t - born[newborn]
            old = va[gone]
            if name == "particle_x":
                old = va[gone] + (t - a.t) * a.particle_v[gone]
            elif name == "particle_age":
                old = va[gone] + (t - a.t)
            out[name] = np.concatenate([old, mid, young])
        order = np.argsort(out["particle_id"], kind="stable")
        return replace(b, t=t, **{name: out[name][order] for name in cls._PER_PARTICLE})
