"""Panels: object roles in the Physics tab, scene settings and Bake/Free in the Scene tab (and
repeated under the object's roles so an animator never has to switch tabs to re-bake)."""
from __future__ import annotations

import bpy

from . import extract, native_points, props
from .props import INTERACTION_TYPES

# larger meshes show their Automatic collider shape only when baking (the panel redraws often)
AUTO_SHAPE_PREVIEW_LIMIT = 100_000


def bake_status(scene) -> tuple[str, str]:
    """(text, icon) telling whether each emitter's and spring mesh's bake matches the scene."""
    from . import farm

    try:
        roles, missing, outdated = farm.bake_state(scene)
    except Exception as exc:  # a panel must draw whatever the scene holds
        return f"Cannot check bake: {exc}", 'ERROR'
    if outdated:
        return f"Bake is outdated (the scene changed): {', '.join(outdated)}", 'ERROR'
    everything = (len(roles.emitters) + len(roles.spring_meshes) + len(roles.rigid_bodies)
                  + len(roles.followers))
    if missing and len(missing) == everything:
        return "Not baked", 'INFO'
    if missing:
        return f"Not baked: {', '.join(missing)}", 'INFO'
    return scene.physanim.bake_info or "Baked", 'CHECKMARK'


def draw_target(layout, p, solved: str) -> None:
    """Hit the Mark's Target and Target Frame; ``solved``: the velocity the bake solves."""
    col = layout.column(align=True)
    col.prop(p, "target")
    if p.target is not None:
        col.prop(p, "target_frame")
        col.label(text=f"{solved} is solved when baking", icon='INFO')


def draw_bake_buttons(layout, scene) -> None:
    from . import resume

    text, icon = bake_status(scene)
    layout.label(text=text, icon=icon)
    cached = resume.status(scene)
    if cached is not None:
        layout.label(text=cached[0], icon='FILE_CACHE')
    row = layout.row(align=True)
    row.operator("physanim.bake", text="Bake", icon='PHYSICS').only_selected = False
    row.operator("physanim.bake", text="Bake Selected").only_selected = True
    row.operator("physanim.free_bake", text="Free", icon='TRASH').only_selected = False
    if cached is not None and cached[1]:
        layout.operator("physanim.bake", text="Resume", icon='PLAY').resume = True


class _PhysicsPanel:
    bl_space_type = 'PROPERTIES'
    bl_region_type = 'WINDOW'
    bl_context = "physics"


class PHYSANIM_PT_object(_PhysicsPanel, bpy.types.Panel):
    bl_label = "PhysAnim"

    @classmethod
    def poll(cls, context):
        return context.object is not None

    def draw(self, context):
        p = context.object.physanim
        row = self.layout.row(align=True)
        row.prop(p.emitter, "enabled", toggle=True, icon='PARTICLES')
        row.prop(p.collider, "enabled", toggle=True, icon='MOD_PHYSICS')
        row.prop(p.force, "enabled", toggle=True, icon='FORCE_WIND')
        if context.object.type == 'MESH':
            row.prop(p.spring_mesh, "enabled", toggle=True, icon='MOD_CLOTH')
            row.prop(p.rigid_body, "enabled", toggle=True, icon='RIGID_BODY')
        row.prop(p.constraint, "enabled", toggle=True, icon='CONSTRAINT')
        row.prop(p.follow, "enabled", toggle=True, icon='CON_FOLLOWPATH')
        draw_bake_buttons(self.layout.box(), context.scene)


class PHYSANIM_PT_emitter(_PhysicsPanel, bpy.types.Panel):
    bl_label = "Emitter"
    bl_parent_id = "PHYSANIM_PT_object"

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.physanim.emitter.enabled

    def draw(self, context):
        ob = context.object
        p = ob.physanim.emitter
        layout = self.layout
        layout.use_property_split = True
        col = layout.column()
        col.prop(p, "source")
        if p.source == 'DEATHS':
            col.prop(p, "parent")
        elif p.source != 'ORIGIN' and ob.type != 'MESH':
            col.label(text="This source needs a mesh object", icon='ERROR')
        elif p.source in ('FACES', 'VOLUME') and ob.type == 'MESH' and not len(ob.data.polygons):
            col.label(text="The mesh has no faces", icon='ERROR')
        col.prop(p, "direction")
        if p.direction == 'AXIS' or (p.direction == 'NORMAL' and p.source in ('ORIGIN', 'VOLUME')):
            col.prop(p, "axis")
        col.prop(p, "spread")
        col = layout.column(align=True)
        col.prop(p, "rate")
        col.prop(p, "rate_random", text="Random")
        col.prop(p, "even_timing")
        col = layout.column(align=True)
        col.prop(p, "frame_start", text="Frame Start")
        col.prop(p, "frame_end", text="End")
        col = layout.column(align=True)
        col.prop(p, "lifetime")
        col.prop(p, "lifetime_random", text="Random")
        col = layout.column(align=True)
        col.prop(p, "speed")
        col.prop(p, "speed_random", text="Random")
        layout.prop(p, "inherit_velocity")
        layout.prop(p, "launch_velocity")
        layout.prop(p, "charge")
        draw_target(layout, p, "Launch Velocity")
        col = layout.column(align=True)
        col.prop(p, "mass")
        col.prop(p, "size")
        col.prop(p, "size_random", text="Random")
        layout.prop(p, "seed")


class PHYSANIM_PT_emitter_look(_PhysicsPanel, bpy.types.Panel):
    bl_label = "Render"
    bl_parent_id = "PHYSANIM_PT_emitter"

    def draw(self, context):
        p = context.object.physanim.emitter
        layout = self.layout
        layout.use_property_split = True
        layout.prop(p, "output")
        note = {'USD_POINTS': ("Plays and renders without PhysAnim (USD files, "
                               f"{native_points.file_extension()[1:]})", 'CHECKMARK'),
                'POINTS': ("Needs PhysAnim wherever it plays or renders", 'INFO'),
                'OBJECTS': ("Keyframed objects: no PhysAnim needed to play", 'CHECKMARK')}
        text, icon = note[p.output]
        layout.label(text=text, icon=icon)
        layout.prop(p, "render_as")
        mode = p.render_as
        if mode in ('OBJECT', 'STREAKS'):
            layout.prop(p, "instance_object")
        if mode == 'GLOW':
            layout.prop(p, "glow_strength")
        elif mode == 'STREAKS':
            layout.prop(p, "streak_time")
        elif mode == 'BILLBOARD':
            layout.template_ID(p, "sprite", open="image.open")
        elif mode == 'BLOBS':
            layout.prop(p, "blob_size")
            layout.prop(p, "blob_resolution")
        if mode == 'OBJECT':
            layout.prop(p, "squash")
            if p.squash > 0.0:
                layout.prop(p, "squash_recovery")
        if mode == 'OBJECT' and p.squash == 0.0:
            layout.prop(p, "stretch")
        if p.result is not None:
            layout.prop(p, "result")
        for curve, stops, field in (('COLOR', p.color_stops, "color"), ('SIZE', p.size_stops, "value")):
            box = layout.box()
            head = box.row()
            head.label(text="Color over Life" if curve == 'COLOR' else "Size over Life")
            add = head.operator("physanim.stop_edit", text="", icon='ADD')
            add.curve, add.action = curve, 'ADD'
            for i, stop in enumerate(stops):
                row = box.row(align=True)
                row.prop(stop, "position", text="")
                row.prop(stop, field, text="")
                rem = row.operator("physanim.stop_edit", text="", icon='REMOVE')
                rem.curve, rem.action, rem.index = curve, 'REMOVE', i


class PHYSANIM_PT_emitter_springs(_PhysicsPanel, bpy.types.Panel):
    bl_label = "Spring Chain"
    bl_parent_id = "PHYSANIM_PT_emitter"
    bl_options = {'DEFAULT_CLOSED'}

    def draw_header(self, context):
        self.layout.prop(context.object.physanim.emitter, "link", text="")

    def draw(self, context):
        p = context.object.physanim.emitter
        layout = self.layout
        layout.use_property_split = True
        layout.active = p.link
        layout.prop(p, "link_hard")
        springs = layout.column()
        springs.active = not p.link_hard
        springs.prop(p, "link_stiffness")
        springs.prop(p, "link_damping")
        layout.prop(p, "link_rest_length")


class PHYSANIM_PT_collider(_PhysicsPanel, bpy.types.Panel):
    bl_label = "Collider"
    bl_parent_id = "PHYSANIM_PT_object"

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.physanim.collider.enabled

    def draw(self, context):
        p = context.object.physanim.collider
        layout = self.layout
        layout.use_property_split = True
        layout.prop(p, "shape")
        if p.shape == 'AUTO':
            ob = context.object
            if ob.type == 'MESH' and len(ob.data.vertices) > AUTO_SHAPE_PREVIEW_LIMIT:
                text, icon = "Collides as: decided when baking", 'INFO'
            else:
                shape = extract.automatic_collider(ob)[0]
                names = {i[0]: i[1] for i in props.COLLIDER_SHAPE_ITEMS}
                text, icon = ((f"Collides as: {names[shape]}", 'INFO') if shape else
                              ("Needs a mesh with faces or an empty", 'ERROR'))
            layout.label(text=text, icon=icon)
        layout.prop(p, "restitution")
        layout.prop(p, "friction")
        layout.prop(p, "thickness")


class PHYSANIM_PT_follow(_PhysicsPanel, bpy.types.Panel):
    bl_label = "Follow-Through"
    bl_parent_id = "PHYSANIM_PT_object"

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.physanim.follow.enabled

    def draw(self, context):
        ob = context.object
        p = ob.physanim.follow
        layout = self.layout
        layout.use_property_split = True
        if ob.parent is None:
            layout.label(text="Parent it to what it should follow", icon='ERROR')
        else:
            layout.label(text=f"Trails {ob.parent.name} (Delta Location keys)", icon='INFO')
        layout.prop(p, "frequency")
        layout.prop(p, "damping")


_INTERACTION_PROPS = {  # what each interaction's panel shows, in order
    'GRAVITY': ("gravity_constant", "softening", "theta"),
    'LENNARD_JONES': ("sigma", "epsilon", "cutoff", "core_softness"),
    'COULOMB': ("coulomb_constant", "cutoff", "softening"),
    'COLLISIONS': ("restitution", "friction"),
}


class PHYSANIM_PT_force(_PhysicsPanel, bpy.types.Panel):
    bl_label = "Force"
    bl_parent_id = "PHYSANIM_PT_object"

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.physanim.force.enabled

    def draw(self, context):
        p = context.object.physanim.force
        layout = self.layout
        layout.use_property_split = True
        layout.prop(p, "type")
        if p.type in INTERACTION_TYPES:
            self._interaction(layout, p)
            return
        layout.label(text="Acts on particles and on spring meshes " + (
            "(pressure on their faces)" if p.type == 'WIND' else "(a whole mesh as one particle)"),
            icon='INFO')
        if p.type == 'DRAG':
            layout.prop(p, "linear")
            layout.prop(p, "quadratic")
            return
        layout.prop(p, "strength")
        if p.type == 'WIND':
            layout.prop(p, "noise")
            sub = layout.column()
            sub.active = p.noise > 0.0
            sub.prop(p, "noise_scale")
            sub.prop(p, "noise_speed")
            sub.prop(p, "seed")
        elif p.type == 'ATTRACTOR':
            layout.prop(p, "falloff")
            layout.prop(p, "min_distance")
            layout.prop(p, "max_distance")

    @staticmethod
    def _interaction(layout, p) -> None:
        layout.prop(p, "affects")
        layout.label(text="Among the particles of " + (
            f'the emitters in "{p.affects.name}"' if p.affects is not None else
            "every emitter") + ", all with all", icon='INFO')
        for key in _INTERACTION_PROPS[p.type]:
            layout.prop(p, key)
        if p.type == 'COULOMB':
            layout.label(text="Each emitter's Charge sets its particles'", icon='INFO')
        if p.type == 'COLLISIONS':
            layout.label(text="Each particle is a sphere of its Size", icon='INFO')


class PHYSANIM_PT_spring_mesh(_PhysicsPanel, bpy.types.Panel):
    bl_label = "Spring Mesh"
    bl_parent_id = "PHYSANIM_PT_object"

    @classmethod
    def poll(cls, context):
        ob = context.object
        return ob is not None and ob.type == 'MESH' and ob.physanim.spring_mesh.enabled

    def draw(self, context):
        ob = context.object
        p = ob.physanim.spring_mesh
        layout = self.layout
        layout.use_property_split = True
        col = layout.column()
        col.prop(p, "mass")
        col.prop(p, "mass_mode")
        col.prop(p, "drag")
        col = layout.column(align=True)
        col.prop(p, "stiffness", text="Edge Stiffness")
        col.prop(p, "damping", text="Damping")
        col.prop(p, "max_stretch")
        faces = len(ob.data.polygons) > 0
        col = layout.column(align=True)
        col.active = faces
        col.prop(p, "shear_stiffness")
        col.prop(p, "shear_damping", text="Damping")
        col = layout.column(align=True)
        col.active = faces
        col.prop(p, "bend_mode")
        if p.bend_mode != 'NONE':
            col.prop(p, "bend_stiffness", text="Stiffness")
            col.prop(p, "bend_damping", text="Damping")
        if not faces:
            layout.label(text="No faces: only edge springs (no shear or bending)", icon='INFO')
        col = layout.column(align=True)
        col.prop(p, "self_collision")
        if p.self_collision:
            col.prop(p, "self_distance")
            col.prop(p, "self_friction")
        layout.prop_search(p, "pin_group", ob, "vertex_groups")
        if p.pin_group:
            layout.prop(p, "pin_stiffness")
        layout.prop(p, "integrator")
        layout.prop(p, "substeps")
        layout.prop(p, "sleep")


class PHYSANIM_PT_spring_virtual(_PhysicsPanel, bpy.types.Panel):
    bl_label = "Virtual Springs"
    bl_parent_id = "PHYSANIM_PT_spring_mesh"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        ob = context.object
        p = ob.physanim.spring_mesh
        layout = self.layout
        add = layout.operator("physanim.virtual_edit", text="Add Virtual Springs", icon='ADD')
        add.action = 'ADD'
        for i, group in enumerate(p.virtual_springs):
            box = layout.box()
            head = box.row()
            head.prop(group, "mode", text="")
            rem = head.operator("physanim.virtual_edit", text="", icon='X')
            rem.action, rem.index = 'REMOVE', i
            box.use_property_split = True
            box.prop_search(group, "vertex_group", ob, "vertex_groups")
            if group.mode != 'PIN':
                box.prop(group, "target")
            if group.mode == 'DISTANCE':
                box.prop(group, "rest_length")
            box.prop(group, "stiffness")
            box.prop(group, "damping")


class PHYSANIM_PT_scene(bpy.types.Panel):
    bl_label = "PhysAnim"
    bl_space_type = 'PROPERTIES'
    bl_region_type = 'WINDOW'
    bl_context = "scene"

    def draw(self, context):
        s = context.scene.physanim
        layout = self.layout
        layout.use_property_split = True
        col = layout.column(align=True)
        col.prop(s, "frame_start", text="Frame Start")
        col.prop(s, "frame_end", text="End")
        layout.prop(s, "time_scale")
        layout.prop(s, "substeps")
        layout.prop(s, "integrator")
        layout.prop(s, "spring_substeps")
        layout.prop(s, "rigid_substeps")
        if s.integrator == 'RK45':
            layout.prop(s, "tolerance")
        layout.prop(s, "seed")
        col = layout.column(align=True, heading="Limits")
        col.prop(s, "world_bound")
        col.prop(s, "speed_limit")
        layout.prop(s, "cache_dir")
        draw_bake_buttons(layout.box(), context.scene)


CLASSES = (PHYSANIM_PT_object, PHYSANIM_PT_emitter, PHYSANIM_PT_emitter_look,
           PHYSANIM_PT_emitter_springs, PHYSANIM_PT_collider, PHYSANIM_PT_follow,
           PHYSANIM_PT_force,
           PHYSANIM_PT_spring_mesh, PHYSANIM_PT_spring_virtual, PHYSANIM_PT_scene)


def _classes() -> tuple:
    from . import rigid_panel  # it builds on this module's classes

    return CLASSES + rigid_panel.CLASSES


def register() -> None:
    for cls in _classes():
        bpy.utils.register_class(cls)


def unregister() -> None:
    for cls in reversed(_classes()):
        bpy.utils.unregister_class(cls)
