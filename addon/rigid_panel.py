"""The Rigid Body panel: the role's settings, the shape it collides as and the mass properties
the bake will use (shown, and overridable)."""
from __future__ import annotations

import bpy
import numpy as np

from ..core.errors import PhysanimError
from .panels import AUTO_SHAPE_PREVIEW_LIMIT, _PhysicsPanel, draw_target
from .rigid_props import POINT_TYPES

SHAPE_NAMES = {"BOX": "Box", "SPHERE": "Sphere", "CAPSULE": "Capsule", "HULL": "Convex Hull",
               "MESH": "Mesh (concave)"}


def _preview(ob):
    """(shape, mass properties) the bake would use, or (None, message)."""
    from ..core.transforms import decompose
    from . import convert, rigid

    p = ob.physanim.rigid_body
    if ob.type != 'MESH':
        return None, "A rigid body must be a mesh"
    if len(ob.data.vertices) > AUTO_SHAPE_PREVIEW_LIMIT:
        return None, "Shape and mass: decided when baking"
    if not len(ob.data.vertices):
        return None, "The mesh has no vertices"
    scale = decompose(convert.matrix(ob.matrix_world))[2]
    co = np.empty(len(ob.data.vertices) * 3, np.float32)
    ob.data.vertices.foreach_get("co", co)
    ob.data.calc_loop_triangles()
    tris = np.empty(len(ob.data.loop_triangles) * 3, np.int32)
    ob.data.loop_triangles.foreach_get("vertices", tris)
    co = co.reshape(-1, 3).astype(np.float64) * np.abs(scale)
    tris = tris.reshape(-1, 3).astype(np.int64)
    shape, params = rigid.shape_of(co, tris, p.shape)
    try:
        return shape, rigid.mass_of(shape, params, p, ob.name, mesh=(co, tris))
    except (PhysanimError, ValueError) as exc:
        return None, str(exc)


class PHYSANIM_PT_rigid_body(_PhysicsPanel, bpy.types.Panel):
    bl_label = "Rigid Body"
    bl_parent_id = "PHYSANIM_PT_object"

    @classmethod
    def poll(cls, context):
        ob = context.object
        return ob is not None and ob.physanim.rigid_body.enabled

    def draw(self, context):
        ob = context.object
        p = ob.physanim.rigid_body
        layout = self.layout
        layout.use_property_split = True
        layout.prop(p, "kinematic")
        layout.prop(p, "shape")
        shape, props = _preview(ob)
        if shape is None:
            layout.label(text=props, icon='ERROR' if "mesh" in props.lower() else 'INFO')
        else:
            layout.label(text=f"Collides as: {SHAPE_NAMES[shape]}, {props.mass:.4g} kg, "
                              f"{props.volume:.4g} m³", icon='INFO')
        col = layout.column(align=True)
        col.prop(p, "use_density")
        col.prop(p, "density" if p.use_density else "mass")
        col = layout.column(align=True)
        col.prop(p, "friction")
        col.prop(p, "restitution")
        col = layout.column(align=True)
        col.prop(p, "linear_damping")
        col.prop(p, "angular_damping")
        col = layout.column(align=True)
        col.active = not p.kinematic
        col.prop(p, "initial_velocity")
        col.prop(p, "initial_angular_velocity")
        draw_target(layout, p, "Initial Velocity")
        col = layout.column(align=True)
        col.prop(p, "squash")
        if p.squash > 0.0:
            col.prop(p, "squash_recovery")
        col = layout.column(align=True)
        col.prop(p, "hang_time")
        col.prop(p, "exaggeration")
        self._mass_overrides(layout, p, shape, props)
        layout.operator("physanim.connect", icon='CONSTRAINT')

    @staticmethod
    def _mass_overrides(layout, p, shape, props) -> None:
        col = layout.column(align=True)
        col.prop(p, "use_custom_com")
        if p.use_custom_com:
            col.prop(p, "com", text="")
        elif shape is not None:
            col.label(text="Center of mass: " + ", ".join(f"{v:.4g}" for v in props.com) + " m")
        col = layout.column(align=True)
        col.prop(p, "use_custom_inertia")
        if p.use_custom_inertia:
            col.prop(p, "inertia", text="")
        elif shape is not None:
            moments = np.diag(props.inertia)
            col.label(text="Inertia: " + ", ".join(f"{v:.4g}" for v in moments) + " kg m²")


class PHYSANIM_PT_constraint(_PhysicsPanel, bpy.types.Panel):
    """A joint placed at this object's origin and axes, as Blender's rigid body constraints."""

    bl_label = "Constraint"
    bl_parent_id = "PHYSANIM_PT_object"

    @classmethod
    def poll(cls, context):
        ob = context.object
        return ob is not None and ob.physanim.constraint.enabled

    def draw(self, context):
        p = context.object.physanim.constraint
        layout = self.layout
        layout.use_property_split = True
        layout.prop(p, "type")
        col = layout.column(align=True)
        col.prop(p, "object1")
        mesh = p.object1 is not None and p.object1.physanim.spring_mesh.enabled
        particles = p.object1 is not None and p.object1.physanim.emitter.enabled
        points = p.type in POINT_TYPES
        if mesh and p.object1.type == 'MESH':
            col.prop_search(p, "group1", p.object1, "vertex_groups")
        if p.type == 'TIE':
            col.prop(p, "reach")
            col.prop(p, "object2")
            if not particles:
                layout.label(text="A Tie holds an emitter's particles (First)", icon='ERROR')
            elif p.object2 is None:
                layout.label(text="Tied to the world", icon='INFO')
            elif p.object2.physanim.rigid_body.enabled:
                layout.label(text=f"\"{p.object2.name}\" swings on the particles and pulls "
                             "them", icon='INFO')
            else:
                layout.label(text=f"Tied to \"{p.object2.name}\" where it is animated",
                             icon='INFO')
            return
        if points:
            if p.type == 'ON_CIRCLE' and context.object.type == 'CURVE':
                col.label(text="The wire is this curve", icon='CURVE_DATA')
            elif p.type != 'ON_PLANE':
                col.prop(p, "radius")
            if not particles:
                layout.label(text="On Plane, On Sphere and On Wire hold an emitter's "
                             "particles (First)", icon='ERROR')
            return
        col.prop(p, "object2")
        if p.object1 is None:
            layout.label(text="Choose the rigid body or spring mesh it holds (First)",
                         icon='ERROR')
        elif particles:
            layout.label(text="An emitter's particles are held On Plane, On Sphere, On Wire "
                         "or by a Tie", icon='ERROR')
        elif mesh and p.type not in ('FIXED', 'BALL'):
            layout.label(text="A spring mesh's vertices are held by Fixed or Ball", icon='ERROR')
        elif p.object2 is None:
            layout.label(text="Held by the world", icon='INFO')
        elif p.object2.physanim.rigid_body.enabled and mesh:
            layout.label(text=f"Hangs on \"{p.object2.name}\", which moves with it", icon='INFO')
        elif not p.object2.physanim.rigid_body.enabled:
            layout.label(text=f"Held by \"{p.object2.name}\" where it is animated", icon='INFO')
        layout.prop(p, "disable_collisions")
        if mesh:  # an attachment: no limits, motors, springs or breaking
            return
        if p.type in ('HINGE', 'SLIDER', 'CONE_TWIST'):
            self._limits(layout, p)
        if p.type == 'SPRING':
            col = layout.column(align=True)
            col.prop(p, "spring_stiffness")
            col.prop(p, "spring_damping")
        if p.type in ('HINGE', 'SLIDER'):
            col = layout.column(align=True)
            col.prop(p, "use_motor")
            if p.use_motor:
                col.prop(p, "motor_velocity")
                col.prop(p, "motor_max")
            col = layout.column(align=True)
            col.prop(p, "use_spring")
            if p.use_spring:
                col.prop(p, "spring_stiffness")
                col.prop(p, "spring_damping")
        col = layout.column(align=True)
        col.prop(p, "use_breaking")
        if p.use_breaking:
            col.prop(p, "break_force")
        if p.broken_frame >= 0:
            layout.label(text=f"Broke at frame {p.broken_frame} in the last bake",
                         icon='UNLINKED')

    @staticmethod
    def _limits(layout, p) -> None:
        col = layout.column(align=True)
        if p.type == 'CONE_TWIST':
            col.prop(p, "cone_angle")
        col.prop(p, "use_limits", text="Twist Limits" if p.type == 'CONE_TWIST' else "Limits")
        if p.use_limits:
            kind = "distance" if p.type == 'SLIDER' else "angle"
            col.prop(p, f"{kind}_lower")
            col.prop(p, f"{kind}_upper")


CLASSES = (PHYSANIM_PT_rigid_body, PHYSANIM_PT_constraint)  # registered by panels.py, after
# their parent panel

