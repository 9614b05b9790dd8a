"""Rigid bodies in Blender: each tagged object -> core body settings (shape from what the user
sees, mass properties from the shape), simulated as one system, streamed per frame into a cache
and written at the end as location / rotation_quaternion keys (:mod:`.rigid_keys`).

Shapes and mass properties are computed in the object's axes with its scale applied, so a
scaled cube is a box of its visible size; the body's orientation is the object's rotation.
"""
from __future__ import annotations

import numpy as np

from ..core.cache import CacheWriter
from ..core.collision.hull import convex_hull
from ..core.contact import ColliderPaths
from ..core.contact.fit import fit_analytic_shape
from ..core.errors import PhysanimError
from ..core.rigid import quaternion as quat
from ..core.rigid.mass import (box_mass, capsule_mass, polyhedron_mass, sphere_mass,
                               with_override)
from ..core.rigid.joints import FRAME, JointSettings
from ..core.rigid.model import RigidBodyBuilder, RigidBodySettings, RigidBodyState
from ..core.rigid.frame_inputs import RigidPaths
from ..core.rigid.solver import RigidBodySolver, RigidBodySystem
from ..core.transforms import decompose
from . import limits
from .cache_paths import rigid_cache_dir
from .extract import world_matrix
from .rigid_props import POINT_TYPES
from .roles import object_kind, type_name
from .mesh_read import evaluated_mesh

STREAM = "bodies"
SPHERE_TOLERANCE = 1e-3  # vertices within this fraction of the radius: the mesh is a sphere
SPHERE_FILL = 0.75  # ... when their hull fills this much of it (a cylinder's rings are all as
# far from its centre too: 0.53; Blender's ico sphere 0.87, UV sphere 0.98)
CONCAVE_FRACTION = 0.9  # a closed mesh with less volume than this of its hull's is concave
FLAT_THICKNESS = 0.01  # a flat mesh (a plane, a card, a disc) is a solid this fraction of its
# size thick (a 2 m plane 2 cm, a 0.4 m card 4 mm), centred on it


def shape_of(co: np.ndarray, tris: np.ndarray, choice: str) -> tuple[str, dict]:
    """The core shape of a mesh (local vertices ``co`` with the object's scale applied) and
    its parameters. Automatic: an axis-aligned box is a BOX, vertices all on a sphere (and
    spread over it: not a cylinder's two rings) a SPHERE, a closed mesh that is clearly
    concave (a ring, a cup, a T) its own MESH, anything else its CONVEX_HULL. A flat mesh as Automatic, Convex Hull or Box is a thin solid
    (:func:`_thin`): what the user sees has no thickness, and a rigid body needs some."""
    lo, hi = co.min(axis=0), co.max(axis=0)
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    hull = convex_hull(co) if len(co) else None
    if choice in ('AUTO', 'CONVEX_HULL', 'BOX') and hull is not None and hull.dimension == 2:
        return _thin(co, hull, centre, half)
    if choice == 'AUTO':
        fitted, _ = fit_analytic_shape(co, tris) if len(tris) else ("MESH", None)
        if fitted == "BOX":
            choice = 'BOX'
        elif _is_sphere(co, hull, centre):
            choice = 'SPHERE'
        else:
            choice = 'MESH' if _concave(co, tris, hull) else 'CONVEX_HULL'
    if choice == 'BOX':
        return "BOX", {"half_extents": tuple(half), "shape_centre": tuple(centre)}
    if choice == 'SPHERE':
        radius = float(np.linalg.norm(co - centre, axis=1).max())
        return "SPHERE", {"radius": radius, "shape_centre": tuple(centre)}
    if choice == 'CAPSULE':
        radius = float(max(half[0], half[1]))
        length = float(max(half[2] - radius, 0.0))
        return "CAPSULE", {"radius": radius, "half_extents": (0.0, 0.0, length),
                           "shape_centre": tuple(centre)}
    if choice == 'MESH':
        return "MESH", {"mesh": (co, np.asarray(tris, np.int64).reshape(-1, 3))}
    if hull is None or hull.dimension < 3:
        return "HULL", {"hull": co}  # a line or a point: the mass properties step says so
    return "HULL", {"hull": hull.points[hull.vertices]}


def _is_sphere(co: np.ndarray, hull, centre: np.ndarray) -> bool:
    """Vertices all on a sphere about the box's centre (within SPHERE_TOLERANCE) whose hull
    fills SPHERE_FILL of it."""
    dist = np.linalg.norm(co - centre, axis=1)
    return bool(len(co) >= 12 and np.ptp(dist) <= SPHERE_TOLERANCE * dist.max()
                and hull.dimension == 3
                and polyhedron_mass(hull.points, hull.triangles, density=1.0).volume
                >= SPHERE_FILL * 4.0 / 3.0 * np.pi * dist.max() ** 3)


def _thin(co: np.ndarray, hull, centre: np.ndarray, half: np.ndarray) -> tuple[str, dict]:
    """A flat mesh (local vertices ``co``, their hull, its box's centre and half extents) as a
    solid FLAT_THICKNESS of its size thick, centred on its plane: a BOX when it is a rectangle
    on the local axes (a plane, a grid), else its outline's hull pushed out both ways along
    its normal (a disc, a card turned in its object)."""
    size = float(2.0 * half.max())
    thick = FLAT_THICKNESS * size
    flat = 2.0 * half <= 1e-6 * size  # (single-precision vertices: flat to their rounding)
    outline = co[hull.vertices]  # its corners
    if flat.sum() == 1:
        axes = np.nonzero(~flat)[0]
        if len(outline) == 4 and np.allclose(np.abs(outline[:, axes] - centre[axes]), half[axes],
                                             rtol=1e-6, atol=1e-6 * size):
            box = half.copy()
            box[flat] = 0.5 * thick
            return "BOX", {"half_extents": tuple(box), "shape_centre": tuple(centre)}
    normal = np.linalg.svd(co - centre, full_matrices=False)[2][-1]  # least-spread direction
    return "HULL", {"hull": np.concatenate([outline + 0.5 * thick * normal,
                                            outline - 0.5 * thick * normal])}


def _concave(co: np.ndarray, tris: np.ndarray, hull) -> bool:
    """A closed, consistently wound mesh whose volume is less than CONCAVE_FRACTION of its
    convex ``hull``'s (open or flat meshes are not: they collide as their hull)."""
    if not len(tris) or hull.dimension < 3:
        return False
    solid = _closed_mesh_mass((co, tris), "mesh", {"density": 1.0})
    if solid is None:
        return False
    return solid.volume < CONCAVE_FRACTION * polyhedron_mass(
        hull.points, hull.triangles, density=1.0).volume


def mass_of(shape: str, params: dict, p, name: str, mesh=None):
    """Mass properties (from density or total mass) with the user's overrides: of the
    analytic shape; for a Mesh body, of its closed mesh (an open one is an error naming the
    shapes that work); for a hull, of the mesh itself when it is closed (``mesh``: local
    vertices and triangles — a concave T-handle weighs as what the user sees, not as its
    hull), else of the hull (an open shell's mass is that of the solid it collides as)."""
    amount = {"density": p.density} if p.use_density else {"mass": p.mass}
    if shape == "BOX":
        props = box_mass(params["half_extents"], **amount)
    elif shape == "SPHERE":
        props = sphere_mass(params["radius"], **amount)
    elif shape == "CAPSULE":
        props = capsule_mass(params["radius"], params["half_extents"][2], **amount)
    else:
        if shape == "MESH":  # must be closed: open or inside out fails, naming the way out
            props = polyhedron_mass(*params["mesh"], name=name, **amount)
        else:
            hull = convex_hull(params["hull"])
            if hull.dimension < 3:
                raise PhysanimError("the mesh is a line or a point (its convex hull has no "
                                    "area) — give it faces", obj=name, kind="rigid body")
            props = _closed_mesh_mass(mesh, name, amount) or \
                polyhedron_mass(hull.points, hull.triangles, name=name, **amount)
        return with_override(props, com=tuple(p.com) if p.use_custom_com else None,
                             inertia=np.diag(p.inertia) if p.use_custom_inertia else None,
                             name=name)
    centre = np.asarray(params["shape_centre"])
    props = with_override(props, com=tuple(centre + props.com))  # the shape's centre
    return with_override(props, com=tuple(p.com) if p.use_custom_com else None,
                         inertia=np.diag(p.inertia) if p.use_custom_inertia else None,
                         name=name)


def _closed_mesh_mass(mesh, name: str, amount: dict):
    """Mass properties of a closed, consistently wound mesh (co, triangles); None when it is
    open, non-manifold, inside out or flat (its hull stands in)."""
    if mesh is None or not len(mesh[1]):
        return None
    try:
        return polyhedron_mass(mesh[0], mesh[1], name=name, **amount)
    except PhysanimError:
        return None


def body_settings(ob, depsgraph, frame: int, shapes: dict | None = None) -> RigidBodySettings:
    """Core settings of a rigid-body object at the bake's first frame. ``shapes``: the shapes
    found so far in this bake, by shape choice, mesh and scale — bodies that share a mesh and
    a scale (duplicates: crates, dominoes, a pile's cubes) have it analysed once. Scales are
    compared in single precision, as the mesh's own vertices are stored: a turned duplicate's
    scale, read back from its world matrix, differs from its twin's in the last digits."""
    if ob.type != 'MESH':
        raise PhysanimError(f"a rigid body must be a mesh object (this is {object_kind(ob)})",
                            obj=ob.name, frame=frame, kind="rigid body")
    p = ob.physanim.rigid_body
    m = world_matrix(ob, frame, "rigid body")
    origin, q, scale = decompose(m)
    if np.any(scale <= 0.0):
        raise PhysanimError(f"its scale {tuple(np.round(scale, 4))} is negative or zero — "
                            "apply a positive scale", obj=ob.name, frame=frame, kind="rigid body")
    mesh = evaluated_mesh(ob, depsgraph, triangles=True)
    if len(mesh.co) == 0:
        raise PhysanimError("the mesh has no vertices", obj=ob.name, frame=frame,
                            kind="rigid body")
    co = mesh.co * scale
    key = (p.shape, scale.astype(np.float32).tobytes(), mesh.co.shape, mesh.co.tobytes(),
           mesh.triangles.tobytes())
    found = shapes.get(key) if shapes is not None else None
    if found is None:
        found = shape_of(co, mesh.triangles, p.shape)
        if shapes is not None:
            shapes[key] = found
    shape, params = found
    try:
        props = mass_of(shape, params, p, ob.name, mesh=(co, mesh.triangles))
        return RigidBodySettings(
            ob.name, shape, props, restitution=p.restitution, friction=p.friction,
            linear_damping=p.linear_damping, angular_damping=p.angular_damping,
            kinematic=p.kinematic, position=tuple(origin), orientation=tuple(q),
            velocity=tuple(p.initial_velocity),
            angular_velocity=tuple(p.initial_angular_velocity), **params)
    except PhysanimError as exc:
        raise PhysanimError(exc.detail, obj=ob.name, frame=frame, kind="rigid body") from exc
    except ValueError as exc:
        raise PhysanimError(str(exc), obj=ob.name, frame=frame, kind="rigid body") from exc


LIMITED = {"HINGE": "angle", "CONE_TWIST": "angle", "SLIDER": "distance"}


def joint_settings(ob, index: dict, frame: int, placed: bool = True) -> JointSettings:
    """Core settings of a constraint object (its origin and axes place the joint) joining the
    rigid bodies ``index`` (name -> body index). ``placed``: read the object's world matrix
    too; the frames after the first read only the keyable values (the joint stays where the
    first frame placed it: :meth:`~physanim.core.rigid.joints.JointModel.with_values`), and
    their settings carry the identity instead, which must not place a joint."""
    p = ob.physanim.constraint

    def fail(message: str):
        raise PhysanimError(message, obj=ob.name, frame=frame, kind="constraint")

    if p.object1 is None or p.object1.name not in index:
        fail("its First object must be a rigid body — choose one in the Constraint panel")
    if p.type in POINT_TYPES:
        fail(f"{type_name(p.type)} holds an emitter's particles, not a rigid body — choose a "
             "joint type, or an emitter as First")
    if p.object2 is not None and p.object2 == p.object1:
        fail("its First and Second objects are the same — choose two different objects")
    body_b = index.get(p.object2.name, FRAME) if p.object2 is not None else FRAME
    limits = LIMITED.get(p.type)
    try:
        return JointSettings(
            ob.name, p.type, index[p.object1.name], body_b,
            world_matrix(ob, frame, "constraint") if placed else np.eye(4),
            use_limits=p.use_limits and limits is not None,
            lower=getattr(p, f"{limits}_lower") if limits else 0.0,
            upper=getattr(p, f"{limits}_upper") if limits else 0.0, cone=p.cone_angle,
            use_motor=p.use_motor, motor_velocity=p.motor_velocity, motor_max=p.motor_max,
            use_spring=p.use_spring or p.type == 'SPRING', stiffness=p.spring_stiffness,
            damping=p.spring_damping,
            break_force=p.break_force if p.use_breaking else float("inf"),
            disable_collisions=p.disable_collisions)
    except PhysanimError as exc:
        raise PhysanimError(exc.detail, obj=ob.name, frame=frame, kind="constraint") from exc


class RigidBake:
    """All rigid bodies of a bake and the constraints joining them, simulated as one system;
    one cache stream for all."""

    def __init__(self, scene, objects: list, inputs_hash: str, constraints: list = ()):
        self.scene, self.objects, self.inputs_hash = scene, objects, inputs_hash
        self.constraints = list(constraints)
        self.writer = CacheWriter(rigid_cache_dir(scene))
        self.system: RigidBodySystem | None = None
        self.holders: dict = {}  # joint -> (holding object, the joint's frame in it)
        self.centres: dict = {}  # frame -> (n, 3) centres of mass, of the frames written last

    @property
    def label(self) -> str:
        names = ", ".join(f'"{ob.name}"' for ob in self.objects)
        return f"rigid bodies ({names})"

    def prepare(self, depsgraph, frame: int, colliders: ColliderPaths) -> None:
        builder = RigidBodyBuilder()
        shapes: dict = {}
        for ob in self.objects:
            builder.add_body(body_settings(ob, depsgraph, frame, shapes))
        index = {ob.name: i for i, ob in enumerate(self.objects)}
        self.index = index
        self.joint_values = [joint_settings(ob, index, frame) for ob in self.constraints]
        for ob, settings in zip(self.constraints, self.joint_values):
            j = builder.add_joint(settings)
            holder = ob.physanim.constraint.object2
            if holder is not None and holder.name not in index:  # an animated object holds it
                self.holders[j] = (holder, np.linalg.inv(world_matrix(holder, frame, "constraint"))
                                   @ world_matrix(ob, frame, "constraint"))
        self.model = builder.finalize()
        self.kinematic = self._animated()
        self.simulated = set(range(len(self.objects))) - set(self.kinematic)
        self.solver = RigidBodySolver(self.model, self.scene.physanim.rigid_substeps,
                                      limits.bounds(self.scene), colliders)
        self.system = RigidBodySystem(self.solver, self.model.state())
        self._last = self.kinematic_matrices(frame)
        self.write_frame(frame)

    def _animated(self) -> list[int]:
        """The bodies whose Animated switch is on now (it is keyframable: the scene is at the
        frame it is read for)."""
        return [i for i, ob in enumerate(self.objects) if ob.physanim.rigid_body.kinematic]

    def kinematic_matrices(self, frame: float) -> dict:
        """The world matrices at ``frame`` (the scene is there) of the animated bodies (by
        body index) and of the joints' frames held by animated objects (by ("joint", index))."""
        out = {i: world_matrix(self.objects[i], frame, "rigid body") for i in self.kinematic}
        for j, (holder, local) in self.holders.items():
            out["joint", j] = world_matrix(holder, frame, "constraint") @ local
        return out

    def begin(self, frame: int, between: list[dict]) -> RigidPaths:
        """The animated bodies' and held joints' paths over the interval to ``frame`` (the
        scene is there; ``between``: their matrices at the sub-frames, read by the bake). A
        body is animated over an interval when its switch is on at the interval's start; the
        switch read at ``frame`` decides the next interval."""
        now = self.kinematic_matrices(frame)

        def path(key):
            return np.stack([self._last[key], *(b[key] for b in between), now[key]])
        paths = {i: path(i) for i in self.kinematic}
        joints = {j: path(("joint", j)) for j in self.holders}
        values = self.joint_values  # read at the interval's start: its limits, motors, ...
        self.kinematic = self._animated()
        self.simulated |= set(range(len(self.objects))) - set(self.kinematic)
        self._last = {**now, **self.kinematic_matrices(frame)}
        # the constraints' keyable values read now steer the next interval
        self.joint_values = [joint_settings(ob, self.index, frame, placed=False)
                             for ob in self.constraints]
        return RigidPaths(paths, joints, values if self.constraints else None)

    def record_breaks(self) -> list[str]:
        """Each constraint's frame of breaking (-1: it held) onto its object; the lines that
        say which broke."""
        broken = self.system.state.joints.joint_broken_frame
        lines = []
        for ob, frame in zip(self.constraints, broken.tolist()):  # frame: the interval's start
            ob.physanim.constraint.broken_frame = frame + 1 if frame >= 0 else -1
            if frame >= 0:
                lines.append(f'constraint "{ob.name}" broke at frame {frame + 1}')
        return lines

    def write_frame(self, frame: int, pose: RigidBodyState | None = None) -> None:
        """Write ``frame``: the bodies now, or ``pose`` (a frame shown between sub-steps, in
        slow motion)."""
        state = self.system.state if pose is None else pose
        self.centres[frame] = state.body_x.copy()  # the frames of the last step (Hit the Mark)
        self.writer.write_frame(STREAM, frame, {
            "position": state.origins(self.model), "rotation": quat.normalized(state.body_q)})

    def flush(self) -> None:
        self.writer.flush()

    def commit(self, meta: dict) -> str:
        return self.writer.commit(dict(meta, kind="rigid_bodies",
                                       objects=[ob.name for ob in self.objects]))

    def detach(self) -> None:
        """Stop, keeping the partial frames for a resume."""
        self.writer.detach()

    def abort(self) -> None:
        self.writer.abort()
