"""Blender scene -> core inputs: which objects play which role, the frozen Model, and the values
of every keyframable property sampled per frame (after ``scene.frame_set``)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.curves import LifeCurve
from ..core.errors import PhysanimError
from ..core.contact import ColliderFrame
from ..core.contact.fit import fit_analytic_shape
from ..core.controls.timing import window_active
from ..core.forces import Attractor, Drag, Vortex, Wind
from ..core.forces.interactions import Coulomb, LennardJones, MutualGravity
from ..core.particles.pair_collisions import ParticleCollisions
from ..core.particles import (EmitterFrame, EmitterSettings, FrameInputs, ParticleModel,
                              ParticleModelBuilder, PointConstraint, SpringLink)
from . import convert, limits
from .curve_wire import curve_wire, wire_ends
from .mesh_read import evaluated_mesh, mesh_polygons
from .props import INTERACTION_TYPES
from .rigid_props import POINT_TYPES
from .roles import Roles, attachments, made_by_bake, object_kind, type_name

MESH_SOURCES = ("VERTS", "FACES", "VOLUME")


def point_constraints(scene, ob, frame: int, depsgraph) -> list:
    """Emitter ``ob``'s particle constraints at ``frame`` (the scene is there): (constraint
    object's name, core kind, world matrix, radius, wire, target) each — plain data, as a
    bake's checkpoint keeps it — or an error naming the constraint. On Wire on a Curve object
    is a wire of the curve's shape (core kind ON_CURVE; ``wire``: its world points and
    whether it is closed, :func:`curve_wire`), else None. A Tie's radius is its Reach and its
    target the Second object's name and world matrix (("", identity): the world); the
    others' target is None."""
    out = []
    for c in attachments(scene, ob, "particles"):
        p = c.physanim.constraint
        if p.type not in POINT_TYPES:
            raise PhysanimError(f"an emitter's particles are held On Plane, On Sphere, On "
                                f"Wire or by a Tie, not by a {type_name(p.type)} joint — "
                                "choose one of those", obj=c.name, frame=frame,
                                kind="constraint")
        radius = float(p.reach if p.type == 'TIE' else p.radius)
        _check_finite(c, frame, "constraint", {"radius": radius})
        m = world_matrix(c, frame, "constraint")
        if p.type == 'ON_CIRCLE' and c.type == 'CURVE':
            out.append((c.name, "ON_CURVE", m, radius, curve_wire(c, m, depsgraph, frame), None))
        elif p.type == 'TIE':
            second = p.object2
            target = ("", np.eye(4)) if second is None else (
                second.name, world_matrix(second, frame, "constraint's Second object"))
            out.append((c.name, "TIE", m, radius, None, target))
        else:
            out.append((c.name, p.type, m, radius, None, None))
    return out


def tie_ends(start, end) -> tuple:
    """PointConstraint's (target, target0, target1) from two :func:`point_constraints`
    targets (None: no tie)."""
    if start is None or end is None:
        return "", np.eye(4), np.eye(4)
    return start[0], start[1], end[1]


def _curve(stops, kind: str) -> LifeCurve:
    ordered = sorted(stops, key=lambda s: s.position)
    if not ordered:
        return LifeCurve.constant(1.0, 1.0, 1.0, 1.0) if kind == "color" else LifeCurve.constant(1.0)
    values = [tuple(s.color) if kind == "color" else (s.value,) for s in ordered]
    return LifeCurve(tuple(s.position for s in ordered), tuple(values))


def automatic_collider(ob) -> tuple[str | None, np.ndarray]:
    """What an Automatic collider collides as: (core shape, local fit matrix); shape None when
    the object cannot collide (no faces, not a mesh). A mesh that may deform (modifiers, shape
    keys) is its own Mesh; otherwise its data *is* its evaluated mesh, read here without a
    depsgraph (so the panel can show the choice): an exact box or filled rectangle becomes that
    analytic shape, anything else the Mesh."""
    if ob.type == 'EMPTY':
        return 'HALF_SPACE', np.eye(4)
    if ob.type != 'MESH' or not len(ob.data.polygons):
        return None, np.eye(4)
    if any(not made_by_bake(m) for m in ob.modifiers) or ob.data.shape_keys:
        return 'MESH', np.eye(4)
    co, start, total, loops = mesh_polygons(ob.data)
    # fan triangles: exact for the convex faces of boxes and rectangles; a concave face only
    # changes the area, and the fit then (conservatively) answers Mesh
    fan = np.repeat(np.arange(len(start)), np.maximum(total - 2, 0))
    k = np.arange(len(fan)) - np.repeat(np.cumsum(np.maximum(total - 2, 0)) - np.maximum(
        total - 2, 0), np.maximum(total - 2, 0))
    tris = np.stack([loops[start[fan]], loops[start[fan] + k + 1], loops[start[fan] + k + 2]], 1)
    return fit_analytic_shape(co, tris)


def world_matrix(ob, frame: float, kind: str) -> np.ndarray:
    """``ob``'s world matrix as numpy; an error naming object, frame and value when it is not
    finite (a NaN key, a driver dividing by zero) or, for colliders, flattened by a zero scale —
    before the core sees it."""
    m = convert.matrix(ob.matrix_world)
    finite = np.isfinite(m).all()
    if not finite or (kind == "collider" and abs(np.linalg.det(m[:3, :3])) < 1e-12):
        location, scale = ob.matrix_world.to_translation(), ob.matrix_world.to_scale()
        what = "became non-finite" if not finite else "has a zero scale (a flat collider)"
        raise PhysanimError(f"its world matrix {what}: location "
                            f"{tuple(round(v, 4) for v in location)}, scale "
                            f"{tuple(round(v, 4) for v in scale)} — check its animation, "
                            "drivers and parents", obj=ob.name, frame=frame, kind=kind)
    limits.check_scale(ob, m, frame, kind)
    return m


def _check_finite(ob, frame: int, kind: str, values: dict) -> None:
    """An error naming object, frame and value when a sampled (keyed or driven) number is NaN or
    infinite; the core would reject it without knowing the frame."""
    for key, value in values.items():
        if isinstance(value, float) and not math.isfinite(value):
            raise PhysanimError(f"{key} is {value} — check its keyframes and drivers",
                                obj=ob.name, frame=frame, kind=kind)


def _framed(name: str, frame: int, kind: str, make, *args):
    """Build a core input with ``make(*args)`` for the object ``name``; its validation error
    gains the frame."""
    try:
        return make(*args)
    except ValueError as exc:
        detail = str(exc).removeprefix(f'{kind} "{name}": ')
        raise PhysanimError(detail, obj=name, frame=frame, kind=kind) from exc


@dataclass
class FrameSample:
    """Per-frame values of every role object (read right after ``frame_set(frame)``).

    ``frame`` is the scene frame (a float between frames in slow motion), ``tau`` the
    simulated time it shows, in frame lengths (:mod:`..core.controls.timing`; the frame itself
    at time scale 1)."""

    frame: float
    emitters: list
    colliders: list
    forces: list
    tau: float | None = None

    def __post_init__(self):
        if self.tau is None:
            self.tau = self.frame


class Extractor:
    """Turns a scene's role objects into a core Model and per-frame FrameInputs.

    Args:
        scene: the scene. roles: from :func:`gather`.
    """

    def __init__(self, scene, roles: Roles):
        self.scene = scene
        self.roles = roles
        self.index = {o.name: i for i, o in enumerate(roles.emitters)}
        self._vertex_counts: dict[str, int] = {}
        self._collider_tris: dict[str, np.ndarray] = {}
        self._collider_counts: dict[str, int] = {}
        self._collider_shapes: dict[str, tuple[str, np.ndarray]] = {}

    def _collider_shape(self, ob, depsgraph, frame: int) -> tuple[str, np.ndarray]:
        """(core shape, local fit matrix) of a collider, decided on its first frame. Automatic
        collides with what the user sees: a mesh that may deform (modifiers, shape keys) or is
        no exact box or rectangle collides as its own evaluated mesh; an empty is the ground."""
        known = self._collider_shapes.get(ob.name)
        if known is not None:
            return known
        shape, fit = ob.physanim.collider.shape, np.eye(4)
        if shape == 'AUTO':
            shape, fit = automatic_collider(ob)
            if shape is None:
                raise PhysanimError(f"an Automatic collider must be a mesh with faces or an "
                                    f"empty (this is {object_kind(ob)}"
                                    f"{' without faces' if ob.type == 'MESH' else ''}) — "
                                    "pick a shape, or give it faces", obj=ob.name, frame=frame,
                                    kind="collider")
        self._collider_shapes[ob.name] = (shape, fit)
        return shape, fit

    def _collider_mesh(self, ob, depsgraph, frame: int) -> np.ndarray:
        """Local vertex positions of a mesh collider's evaluated (deformed) mesh at this frame;
        its triangles are read once and the vertex count must not change."""
        if ob.type != 'MESH':
            raise PhysanimError(f"a Mesh collider must be a mesh object (this is "
                                f"{object_kind(ob)})",
                                obj=ob.name, frame=frame, kind="collider")
        first = ob.name not in self._collider_tris
        mesh = evaluated_mesh(ob, depsgraph, triangles=first)
        verts, tris = mesh.co, mesh.triangles
        if first:
            if len(tris) == 0:
                raise PhysanimError("a Mesh collider needs faces (this mesh has none)",
                                    obj=ob.name, frame=frame, kind="collider")
            self._collider_tris[ob.name] = tris
            self._collider_counts[ob.name] = len(verts)
        elif len(verts) != self._collider_counts[ob.name]:
            raise PhysanimError(f"the mesh changed its vertex count to {len(verts)} (was "
                                f"{self._collider_counts[ob.name]}) — mesh colliders must keep "
                                "their topology", obj=ob.name, frame=frame, kind="collider")
        if not np.all(np.isfinite(verts)):
            bad = int(np.argwhere(~np.isfinite(verts))[0][0])
            raise PhysanimError(f"vertex {bad} has a non-finite position {verts[bad].tolist()}",
                                obj=ob.name, frame=frame, kind="collider")
        return verts

    def _uses_mesh(self, ob) -> bool:
        return ob.physanim.emitter.source in MESH_SOURCES

    def build_model(self, depsgraph, frame: int) -> ParticleModel:
        """The frozen Model: emitter topology and static settings at the bake's start frame."""
        builder = ParticleModelBuilder(seed=self.scene.physanim.seed)
        for ob in self.roles.emitters:
            p = ob.physanim.emitter
            tris, nverts = np.zeros((0, 3), np.int64), 0
            if self._uses_mesh(ob):
                if ob.type != 'MESH':
                    raise PhysanimError(f"source {p.source} needs a mesh object (this is "
                                        f"{object_kind(ob)})",
                                        obj=ob.name, frame=frame, kind="emitter")
                mesh = evaluated_mesh(ob, depsgraph, triangles=True)
                verts, tris = mesh.co, mesh.triangles
                nverts = len(verts)
                self._vertex_counts[ob.name] = nverts
            parent = None
            if p.source == 'DEATHS':
                if p.parent is None or p.parent.name not in self.index:
                    raise PhysanimError("source is Particle Deaths but its parent is not an emitter "
                                        "of this scene — pick a parent emitter",
                                        obj=ob.name, frame=frame, kind="emitter")
                parent = self.index[p.parent.name]
            link = None
            if p.link:
                link = SpringLink(p.link_stiffness, p.link_damping, p.link_rest_length,
                                  p.link_hard)
            builder.add_emitter(EmitterSettings(
                name=ob.name, source=p.source, direction=p.direction,
                axis=convert.AXES[p.axis], seed=p.seed, parent=parent, triangles=tris,
                vertex_count=nverts, color=_curve(p.color_stops, "color"),
                size=_curve(p.size_stops, "size"), stretch=p.stretch, link=link,
                even=p.even_timing))
        return builder.finalize(frame)

    def sample(self, depsgraph, frame: float, emitters: bool = True,
               tau: float | None = None) -> FrameSample:
        """Read every keyframable value at ``frame`` (the scene must already be at that frame);
        ``emitters`` False leaves the emitters out (see :meth:`sample_emitters`); ``tau``: the
        simulated time the frame shows (default: the frame)."""
        return FrameSample(frame, self.sample_emitters(depsgraph, frame) if emitters else [],
                           *self._sample_world(depsgraph, frame), tau=tau)

    def sample_emitters(self, depsgraph, frame: float, since: float | None = None) -> list:
        """The emitters' values at ``frame``, the end of the interval from ``since`` (default
        one frame before): what only the particle system reads (a failure here is that
        system's, not the spring meshes')."""
        emitters = []
        for ob in self.roles.emitters:
            p = ob.physanim.emitter
            verts = None
            if self._uses_mesh(ob):
                verts = evaluated_mesh(ob, depsgraph).co
                expected = self._vertex_counts.get(ob.name)
                if expected is not None and len(verts) != expected:
                    raise PhysanimError(f"the mesh changed its vertex count to {len(verts)} "
                                        f"(was {expected}) — emitter meshes must keep their topology",
                                        obj=ob.name, frame=frame, kind="emitter")
            values = {k: float(getattr(p, k)) for k in (
                "rate", "rate_random", "lifetime", "lifetime_random", "speed", "speed_random",
                "mass", "size", "size_random", "spread", "inherit_velocity", "charge")}
            _check_finite(ob, frame, "emitter", values)
            launch = tuple(float(v) for v in p.launch_velocity)
            _check_finite(ob, frame, "emitter", {f"launch_velocity[{i}]": v
                                                 for i, v in enumerate(launch)})
            values["launch"] = launch
            for key, unit in (("lifetime", "frames"), ("size", "m")):
                if values[f"{key}_random"] > values[key]:
                    raise PhysanimError(
                        f"{key}_random {values[key + '_random']:g} {unit} is larger than {key} "
                        f"{values[key]:g} {unit}: values would become negative — lower "
                        f"{key}_random or raise {key}", obj=ob.name, frame=frame, kind="emitter")
            values["active"] = window_active(p.frame_start, p.frame_end,  # this interval's
                                             frame - 1 if since is None else since, frame)
            values["constraints"] = point_constraints(self.scene, ob, frame, depsgraph)
            emitters.append((world_matrix(ob, frame, "emitter"), verts, values))
        return emitters

    def _sample_world(self, depsgraph, frame: int) -> tuple[list, list]:
        """Colliders and force objects at ``frame``: what every system reads."""
        colliders = []
        for ob in self.roles.colliders:
            c = ob.physanim.collider
            _check_finite(ob, frame, "collider", {"restitution": c.restitution,
                                                   "friction": c.friction, "thickness": c.thickness})
            shape, fit = self._collider_shape(ob, depsgraph, frame)
            verts = self._collider_mesh(ob, depsgraph, frame) if shape == 'MESH' else None
            colliders.append((world_matrix(ob, frame, "collider") @ fit, shape, c.restitution,
                              c.friction, c.thickness, verts))
        forces = []
        for ob in self.roles.forces:
            values = {k: getattr(ob.physanim.force, k) for k in (
                "type", "strength", "noise", "noise_scale", "noise_speed", "linear",
                "quadratic", "falloff", "min_distance", "max_distance", "seed",
                "gravity_constant", "theta", "softening", "sigma", "epsilon", "cutoff",
                "core_softness", "coulomb_constant", "restitution", "friction")}
            _check_finite(ob, frame, "force", values)
            values["emitters"] = self._affected(ob)
            forces.append((world_matrix(ob, frame, "force"), values))
        return colliders, forces

    def emitter_motion(self) -> list:
        """World matrices of the emitters at the current (sub-)frame."""
        frame = self.scene.frame_current_final
        return [world_matrix(ob, frame, "emitter") for ob in self.roles.emitters]

    def sample_motion(self, emitters: bool = True) -> tuple[list, list]:
        """World matrices of emitters (none when ``emitters`` is False) and colliders at the
        current (sub-)frame."""
        frame = self.scene.frame_current_final
        return (self.emitter_motion() if emitters else [],
                [world_matrix(ob, frame, "collider") @ self._collider_shapes[ob.name][1]
                 for ob in self.roles.colliders])

    def inputs(self, a: FrameSample, b: FrameSample, between: list | None = None) -> FrameInputs:
        """Core inputs for the interval from sample ``a`` to sample ``b`` (the next frame).

        Args:
            between: :meth:`sample_motion` results at evenly spaced sub-frames strictly between
                ``a`` and ``b``, so curved motion is followed within the frame.
        """
        def seconds(frames):
            return convert.frames_to_seconds(self.scene, frames)

        between = between or []

        def keys(kind: int, i: int, m0, m1):
            if not between:
                return None
            return np.stack([m0] + [mid[kind][i] for mid in between] + [m1])

        emitters = []
        # the interval's births are frame b's: they use the emitter's values at b
        for i, ((m0, v0, start), (m1, v1, val)) in enumerate(zip(a.emitters, b.emitters)):
            held = tuple(_framed(name, a.frame, "constraint", PointConstraint, name, kind, ma, mb,
                                 radius, *wire_ends(wa, wb), *tie_ends(ta, tb))
                         for (name, kind, ma, _, wa, ta), (_, _, mb, radius, wb, tb)
                         in zip(start["constraints"], val["constraints"]))
            emitters.append(EmitterFrame(
                rate=val["rate"], rate_random=val["rate_random"], speed=val["speed"],
                speed_random=val["speed_random"], lifetime=seconds(val["lifetime"]),
                lifetime_random=seconds(val["lifetime_random"]), mass=val["mass"],
                size=val["size"], size_random=val["size_random"], spread=val["spread"],
                inherit_velocity=val["inherit_velocity"], launch=val["launch"],
                active=val["active"],
                matrix0=m0, matrix1=m1, matrices=keys(0, i, m0, m1), verts0=v0, verts1=v1,
                constraints=held))
        colliders = [_framed(ob.name, a.frame, "collider", ColliderFrame,
                             ob.name, shape, m0, m1, rest, fric, keys(1, i, m0, m1), thick,
                             v0, v1, self._collider_tris.get(ob.name))
                     for i, (ob, (m0, shape, rest, fric, thick, v0), (m1, *_, v1))
                     in enumerate(zip(self.roles.colliders, a.colliders, b.colliders))]
        fields = [(ob, m, f) for ob, (m, f) in zip(self.roles.forces, a.forces)
                  if f["type"] not in INTERACTION_TYPES]
        forces = [_framed(ob.name, a.frame, "force", self._force, ob, m, f)
                  for ob, m, f in fields]
        charges = tuple(values["charge"] for *_, values in b.emitters)
        among = [_framed(ob.name, a.frame, "force", _interaction, ob, f, charges)
                 for ob, (_, f) in zip(self.roles.forces, a.forces)
                 if f["type"] in INTERACTION_TYPES and b.emitters]
        collisions = [c for c in among if isinstance(c, ParticleCollisions)]
        interactions = [c for c in among if not isinstance(c, ParticleCollisions)]
        return FrameInputs(frame=a.frame, t0=seconds(a.tau),
                           frame_dt=seconds(b.tau - a.tau),
                           gravity=convert.gravity(self.scene), emitters=emitters,
                           colliders=colliders, forces=forces, interactions=interactions,
                           collisions=collisions)

    def _affected(self, ob) -> tuple[int, ...]:
        """The emitter indices an interaction force object's Emitters collection holds (all
        emitters: empty)."""
        group = ob.physanim.force.affects
        if group is None:
            return ()
        names = {o.name for o in group.all_objects}
        return tuple(i for name, i in self.index.items() if name in names) or (-1,)

    @staticmethod
    def _force(ob, m: np.ndarray, f: dict):
        z_axis = tuple(m[:3, 2])
        origin = tuple(m[:3, 3])
        kind = f["type"]
        if kind == 'WIND':
            return Wind(ob.name, z_axis, f["strength"], f["noise"], f["noise_scale"],
                        f["noise_speed"], f["seed"])
        if kind == 'DRAG':
            return Drag(ob.name, f["linear"], f["quadratic"])
        if kind == 'ATTRACTOR':
            return Attractor(ob.name, origin, f["strength"], f["falloff"], f["min_distance"],
                             f["max_distance"])
        return Vortex(ob.name, origin, z_axis, f["strength"])


def _interaction(ob, f: dict, charges: tuple[float, ...]):
    """A force object's interaction among particles (its type in INTERACTION_TYPES)."""
    kind, members = f["type"], f["emitters"]
    if kind == 'GRAVITY':
        return MutualGravity(ob.name, G=f["gravity_constant"], softening=f["softening"],
                             theta=f["theta"], emitters=members)
    if kind == 'COLLISIONS':
        return ParticleCollisions(ob.name, restitution=f["restitution"], friction=f["friction"],
                                  emitters=members)
    if kind == 'LENNARD_JONES':
        return LennardJones(ob.name, sigma=f["sigma"], epsilon=f["epsilon"], cutoff=f["cutoff"],
                            softness=f["core_softness"], emitters=members)
    return Coulomb(ob.name, k=f["coulomb_constant"], cutoff=f["cutoff"],
                   softening=f["softening"], charges=charges, emitters=members)
