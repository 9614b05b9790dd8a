"""Spring meshes in Blender: extract a mesh object into a core spring-mesh model, bake it frame
by frame into a PC2 file, and play it back with a native Mesh Cache modifier named ``physanim``.

Simulation happens in world space (so an object's own animation and parenting are honoured);
the cache holds object-space positions (sample 0 = the bake's first frame), which the modifier
plays back exactly: evaluated vertex f == cached sample f. Modifiers above ``physanim`` in the
stack shape the rest mesh (inputs); modifiers below it deform the played-back result.
"""
from __future__ import annotations

import os

import bpy
import numpy as np

from ..core.cache import CacheWriter
from ..core.errors import PhysanimError
from ..core.contact import ColliderPaths
from ..core.pc2 import Pc2Writer
from ..core.springs import (Attachment, SpringDrive, SpringMeshBuilder, SpringMeshSettings,
                            SpringMeshSolver, SpringMeshSystem, VirtualSprings)
from ..core.transforms import inverse_affine, transform_points
from . import convert, limits
from .cache_paths import spring_cache_dir
from .extract import world_matrix
from .roles import attachments, object_kind, type_name
from .mesh_read import evaluated_mesh

MODIFIER = "physanim"
CACHE_FILE = "mesh.pc2"


def cache_modifier(ob):
    """The Mesh Cache modifier a bake added to ``ob`` (None when there is none)."""
    mod = ob.modifiers.get(MODIFIER)
    return mod if mod is not None and mod.type == 'MESH_CACHE' else None


def _object_matrix(ob, frame: int) -> np.ndarray:
    """World matrix of a spring mesh; an error naming object, frame and value when it is not
    finite or has a zero scale (the cache holds object-space positions: it needs the inverse)."""
    m = world_matrix(ob, frame, "spring mesh")
    if abs(np.linalg.det(m[:3, :3])) < 1e-12:
        scale = tuple(round(v, 4) for v in ob.matrix_world.to_scale())
        raise PhysanimError(f"its world matrix has a zero scale {scale}: the cache holds "
                            "object-space positions, which a flattened object cannot map back — "
                            "check its animation, drivers and parents",
                            obj=ob.name, frame=frame, kind="spring mesh")
    return m


ATTACHABLE = ('FIXED', 'BALL')  # joints that hold points (a vertex has no orientation)


def attachment(constraint, weights: dict, count: int, frame: int) -> Attachment:
    """The core attachment a constraint object makes of its First spring mesh's vertex group
    (all vertices when it names none), held on its Second object (None: the world)."""
    p = constraint.physanim.constraint

    def fail(message: str):
        raise PhysanimError(message, obj=constraint.name, frame=frame, kind="constraint")

    if p.type not in ATTACHABLE:
        fail(f"a spring mesh's vertices can only be held (Fixed or Ball), not by "
             f"{type_name(p.type)} — choose Fixed or Ball")
    if p.object2 is not None and p.object2 == p.object1:
        fail("its First and Second objects are the same — choose two different objects")
    if p.use_breaking:
        fail("a spring mesh's attachment cannot break (breaking is for joints between rigid "
             "bodies) — turn Breakable off")
    if not p.group1:
        index = np.arange(count)
    elif p.group1 not in weights:
        fail(f'"{p.group1}" is not a vertex group of "{p.object1.name}"')
    else:
        index = np.nonzero(weights[p.group1] > 0.0)[0]
        if not len(index):
            fail(f'the vertex group "{p.group1}" of "{p.object1.name}" has no vertices')
    return Attachment(index, None if p.object2 is None else p.object2.name,
                      collide=not p.disable_collisions)


class SpringMeshBake:
    """Bake of one spring-mesh object.

    Args:
        scene, ob: the scene and the mesh object (its cache folder is opened here).
        frame: bake start frame. settings: scene.physanim.
    """

    def __init__(self, scene, ob, frame: int, colliders: ColliderPaths):
        if ob.type != 'MESH':
            raise PhysanimError(f"a spring mesh must be a mesh object (this is "
                                f"{object_kind(ob)})",
                                obj=ob.name, frame=frame, kind="spring mesh")
        self.scene, self.ob = scene, ob
        self.writer = CacheWriter(spring_cache_dir(scene, ob))
        self.colliders = colliders  # the bake's, shared with its other systems
        p = ob.physanim.spring_mesh
        self.props = p
        self.groups = [v for v in p.virtual_springs]
        self.attachments = attachments(scene, ob)  # constraint objects holding its vertices
        self.needs_rest = bool(p.pin_group) or any(v.mode == 'PIN' for v in self.groups)
        held_on = {c.physanim.constraint.object2.name: "attachment target"
                   for c in self.attachments if c.physanim.constraint.object2 is not None}
        pulled_to = {v.target.name: "virtual spring target" for v in self.groups
                     if v.mode != 'PIN' and v.target is not None}
        self.target_kinds = {**held_on, **pulled_to}  # what messages call each target
        self.targets = sorted(self.target_kinds)
        self.pc2: Pc2Writer | None = None
        self.asleep_from: int | None = None  # the frame from which the mesh sleeps (at rest)

    @property
    def label(self) -> str:
        """What a failure report calls this system."""
        return f'spring mesh "{self.ob.name}"'

    # --- set-up --------------------------------------------------------------------------------
    def prepare(self, depsgraph, frame: int) -> None:
        ob, p, s = self.ob, self.props, self.scene.physanim
        mesh = evaluated_mesh(ob, depsgraph, topology=True)
        m = _object_matrix(ob, frame)
        rest = transform_points(m, mesh.co)
        weights = mesh.weights
        pin = None
        if p.pin_group:
            if p.pin_group not in weights:
                raise PhysanimError(f'pin group "{p.pin_group}" is not a vertex group of the mesh',
                                    obj=ob.name, frame=frame, kind="spring mesh")
            pin = weights[p.pin_group]
        settings = SpringMeshSettings(
            ob.name, mass=p.mass, mass_mode=p.mass_mode, stiffness=p.stiffness, damping=p.damping,
            shear_stiffness=p.shear_stiffness, shear_damping=p.shear_damping,
            bend_mode=p.bend_mode, bend_stiffness=p.bend_stiffness, bend_damping=p.bend_damping,
            drag=p.drag, pin_stiffness=p.pin_stiffness, max_stretch=p.max_stretch,
            self_collision=p.self_collision, self_distance=p.self_distance,
            self_friction=p.self_friction, sleep=p.sleep)
        builder = SpringMeshBuilder(settings, rest, mesh.edges, mesh.triangles, mesh.loop_start,
                                    mesh.loop_total, mesh.loop_vertices, pin)
        if pin is not None:
            soft = (pin > 0.0) & (pin < 0.999)
            if soft.any():
                builder.add_virtual(VirtualSprings("PIN", np.nonzero(soft)[0], pin[soft], 0.0,
                                                   p.pin_stiffness, 0.1 * p.pin_stiffness ** 0.5))
        for k, group in enumerate(self.groups):
            self._add_group(builder, k, group, weights, frame)
        for c in self.attachments:
            builder.add_attachment(attachment(c, weights, len(rest), frame))
        self.model = builder.finalize(frame)
        integrator = s.integrator if p.integrator == 'SCENE' else p.integrator
        substeps = p.substeps or s.spring_substeps
        self.solver = SpringMeshSolver(self.model, integrator, substeps, s.tolerance,
                                       convert.seconds_per_frame(self.scene), frame,
                                       limits.bounds(self.scene), self.colliders)
        self.state = self.model.state()
        self.system = SpringMeshSystem(self.solver, self.state)
        self.vertex_count = len(rest)
        self.pc2 = Pc2Writer(self.writer.file_path(CACHE_FILE), self.vertex_count, frame)
        self.sample = self.read(depsgraph, frame)
        self.write()

    def _add_group(self, builder, k: int, group, weights: dict, frame: int) -> None:
        ob = self.ob
        where = f"virtual spring group {k + 1}"
        if group.vertex_group not in weights:
            raise PhysanimError(f'{where}: "{group.vertex_group}" is not a vertex group of the mesh',
                                obj=ob.name, frame=frame, kind="spring mesh")
        if group.mode != 'PIN' and group.target is None:
            raise PhysanimError(f"{where}: {group.mode.lower()} springs need a target object",
                                obj=ob.name, frame=frame, kind="spring mesh")
        w = weights[group.vertex_group]
        index = np.nonzero(w > 0.0)[0]
        builder.add_virtual(VirtualSprings(
            group.mode, index, w[index], group.rest_length, group.stiffness, group.damping,
            None if group.mode == 'PIN' else group.target.name))

    # --- per frame -----------------------------------------------------------------------------
    def read(self, depsgraph, frame: int) -> dict:
        """What this mesh needs from the scene at ``frame``: its world matrix, its animated rest
        shape (world, for pins) and its virtual-spring targets' matrices."""
        ob = self.ob
        # a NaN key or driver must stop the bake here, naming the object and the frame: the
        # solver would report a blow-up a frame early, and an unpinned mesh would write NaN
        m = _object_matrix(ob, frame)
        out = {"frame": frame, "matrix": m, "rest": None,
               "targets": {name: world_matrix(bpy.data.objects[name], frame,
                                               self.target_kinds[name])
                           for name in self.targets}}
        if self.needs_rest:
            co = evaluated_mesh(ob, depsgraph).co
            if len(co) != self.vertex_count:
                raise PhysanimError(f"the mesh changed its vertex count to {len(co)} (was "
                                    f"{self.vertex_count}) — spring meshes must keep their topology",
                                    obj=ob.name, frame=frame, kind="spring mesh")
            out["rest"] = transform_points(m, co)
        return out

    def drive(self, nxt: dict) -> SpringDrive:
        """This mesh's own input for the interval from its last sample to ``nxt``."""
        a = self.sample
        return SpringDrive(a["rest"], nxt["rest"],
                           {n: (a["targets"][n], nxt["targets"][n]) for n in self.targets})

    def end_frame(self, nxt: dict) -> None:
        """The interval to ``nxt`` was simulated (its frames are written by :meth:`write`)."""
        self.sample = nxt
        if not self.solver.asleep:
            self.asleep_from = None
        elif self.asleep_from is None:
            self.asleep_from = nxt["frame"]

    def write(self, frame: int | None = None, pose=None) -> None:
        """Append a frame's object-space positions to the PC2 file: the state now, or ``pose``
        (a frame shown between sub-steps, in slow motion). Positions are in the object's space
        at that frame."""
        matrix = self.sample["matrix"]
        if pose is not None:
            matrix = _object_matrix(self.ob, frame)  # the scene is past it: evaluate there
        x = self.state.x if pose is None else pose.x
        local = transform_points(inverse_affine(matrix), x)
        if not np.isfinite(local).all():  # nothing non-finite is ever written to a bake
            bad = int(np.argmax(~np.isfinite(local).all(axis=1)))
            raise PhysanimError(f"vertex {bad} became {local[bad].tolist()} in object space — "
                                "check the object's scale and animation", obj=self.ob.name,
                                frame=self.sample["frame"] if frame is None else frame,
                                kind="spring mesh")
        self.pc2.append(local)

    def close(self) -> None:
        solver = getattr(self, "solver", None)  # (none yet where the set-up failed)
        if solver is not None:
            solver.close()
        if self.pc2 is not None:
            self.pc2.close()

    def commit(self, meta: dict) -> str:
        """Swap the new cache in; returns its folder."""
        self.close()
        return self.writer.commit(meta)

    def detach(self) -> None:
        """Stop, keeping the partial cache for a resume; the previous bake stays as it was."""
        self.close()
        self.writer.detach()

    def abort(self) -> None:
        """Delete the partial cache; the previous bake stays as it was."""
        self.close()
        self.writer.abort()


# --- result: the Mesh Cache modifier ------------------------------------------------------------

def suspend_modifier(ob) -> dict | None:
    """Read the mesh as the cache modifier sees it while baking: disable it and every modifier
    after it (those deform the cached result, they are not inputs). Returns what to restore."""
    mod = cache_modifier(ob)
    if mod is None:
        return None
    index = ob.modifiers.find(MODIFIER)
    state = {m.name: (m.show_viewport, m.show_render) for m in list(ob.modifiers)[index:]}
    for m in list(ob.modifiers)[index:]:
        m.show_viewport = m.show_render = False
    return state


def restore_modifier(ob, state: dict | None) -> None:
    for name, (viewport, render) in (state or {}).items():
        mod = ob.modifiers.get(name)
        if mod is not None:
            mod.show_viewport, mod.show_render = viewport, render


def attach(ob, pc2_path: str, frame_start: int, inputs_hash: str, suspended: dict | None) -> None:
    """Add (or update) the ``physanim`` Mesh Cache modifier playing the PC2 file: frame
    ``frame_start`` shows sample 0 (the guide's frame mapping). A new one goes last in the stack;
    an existing one keeps its place, and the modifiers after it (suspended during the bake) are
    switched back on: they deform the cached result (e.g. a Solidify for rendering)."""
    mod = cache_modifier(ob)
    if mod is None:
        mod = ob.modifiers.new(MODIFIER, 'MESH_CACHE')
    mod.cache_format = 'PC2'
    mod.filepath = pc2_path
    mod.time_mode = 'FRAME'
    mod.play_mode = 'SCENE'
    mod.frame_start = frame_start
    mod.frame_scale = 1.0
    mod.interpolation = 'LINEAR'
    mod.deform_mode = 'OVERWRITE'
    mod.forward_axis, mod.up_axis = 'POS_Y', 'POS_Z'
    restore_modifier(ob, suspended)
    mod.show_viewport = mod.show_render = True
    ob.physanim.spring_mesh.bake_hash = inputs_hash


def free(ob) -> bool:
    """Remove the cache modifier (and nothing else of the object). True when there was one."""
    mod = cache_modifier(ob)
    if mod is None:
        return False
    ob.modifiers.remove(mod)
    ob.physanim.spring_mesh.bake_hash = ""
    return True


def cache_folder_of(ob) -> str | None:
    mod = cache_modifier(ob)
    if mod is None or not mod.filepath:
        return None
    return os.path.dirname(bpy.path.abspath(mod.filepath, library=ob.library))


def rest_notes(meshes) -> list[str]:
    """For the bake's summary: the meshes asleep at its end, and since which frame."""
    return [f'"{m.ob.name}" at rest (asleep) from frame {m.asleep_from}' for m in meshes
            if m.asleep_from is not None]
