"""Operators: ``physanim.bake`` and ``physanim.free_bake`` (DESIGN.md), plus curve-stop editing.

In the UI the bake is modal: a timer steps one frame at a time, the progress bar moves, ESC
cancels and keeps the previous bake. In background mode (and from scripts and the CLI) it runs
synchronously and returns {'FINISHED'} or {'CANCELLED'} with an error report.
"""
from __future__ import annotations

import time

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty

from ..core.errors import PhysanimError
from . import bake, cache_paths, follow, results, resume, rigid_keys, springs

FRAME_BUDGET_S = 0.05  # modal: simulate for at most this long per timer tick, then redraw


def _selected_names(context) -> set[str]:
    return {o.name for o in context.selected_objects
            if o.physanim.emitter.enabled or o.physanim.spring_mesh.enabled
            or o.physanim.rigid_body.enabled}


class PHYSANIM_OT_bake(bpy.types.Operator):
    """Bake every PhysAnim system of the scene into its cache and native results"""

    bl_idname = "physanim.bake"
    bl_label = "Bake PhysAnim"
    bl_options = {'REGISTER', 'UNDO'}

    only_selected: BoolProperty(name="Only Selected", default=False,
                                description="Bake only the selected emitters (and their parents)")
    resume: BoolProperty(name="Resume", default=False,
                         description="Go on from the last checkpoint: a cut-off bake continues "
                                     "where it stopped, a finished one extends to the frame end")

    _job = None
    _timer = None

    def _make_job(self, context):
        only = _selected_names(context) if self.only_selected else None
        if only is not None and not only:
            raise PhysanimError("no selected object is a PhysAnim emitter", obj=context.scene.name,
                                kind="scene")
        return bake.BakeJob(context, only, self.resume)

    def execute(self, context):
        only = _selected_names(context) if self.only_selected else None
        wm = context.window_manager

        def progress(job):
            if job.frame == job.frame_start:
                wm.progress_begin(0, max(1, job.total_frames))
            wm.progress_update(job.frame - job.frame_start)
            if bpy.app.background:
                print(f"PhysAnim: frame {job.frame}/{job.frame_end} "
                      f"({job.contents})", flush=True)

        try:
            if only is not None and not only:
                raise PhysanimError("no selected object is a PhysAnim emitter",
                                    obj=context.scene.name, kind="scene")
            info, failed = bake.run(context, only, progress, self.resume)
        except (PhysanimError, OSError, ValueError) as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        finally:
            wm.progress_end()
        self.report({'ERROR'} if failed else {'INFO'}, failed or info)
        return {'FINISHED'}

    def invoke(self, context, event):
        if bpy.app.background:
            return self.execute(context)
        try:
            self._job = self._make_job(context)
        except (PhysanimError, OSError, ValueError) as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        wm = context.window_manager
        wm.progress_begin(0, max(1, self._job.total_frames))
        self._timer = wm.event_timer_add(0.0, window=context.window)
        wm.modal_handler_add(self)
        return {'RUNNING_MODAL'}

    def modal(self, context, event):
        if event.type == 'ESC':
            job, self._job = self._job, None
            try:
                job.suspend()  # the frames so far stay for Resume
                note = f"frames up to {job.frame} kept: Resume goes on from there"
            except Exception as exc:  # nothing to keep, or no room for it
                note = f"nothing kept ({exc})"
            self._end(context)
            self.report({'WARNING'}, f"PhysAnim bake cancelled; the previous bake is unchanged; "
                                     f"{note}")
            return {'CANCELLED'}
        if event.type != 'TIMER':
            # Swallow other input while baking: an undo, delete or scene switch mid-bake would
            # pull data from under the job. The UI still redraws between timer ticks.
            return {'RUNNING_MODAL'}
        job = self._job
        try:
            deadline = time.perf_counter() + FRAME_BUDGET_S
            done = False
            while not done and time.perf_counter() < deadline:
                done = job.step(context)
            context.window_manager.progress_update(job.frame - job.frame_start)
            context.workspace.status_text_set(
                f"PhysAnim: baking frame {job.frame}/{job.frame_end} — "
                f"{job.contents} (Esc to stop; Resume goes on later)")
            if not done:
                return {'RUNNING_MODAL'}
            info = job.finish(context)
        except Exception as exc:  # any failure must clean up and keep the old bake
            self.cancel(context)
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        self._end(context)
        failed = job.failure_report(info)
        self.report({'ERROR'} if failed else {'INFO'}, failed or info)
        return {'FINISHED'}

    def cancel(self, context):
        """Esc, an error, or Blender cancelling the operator (e.g. loading a file): drop the
        partial bake and leave the previous one as it was."""
        if self._job is not None:
            self._job.abort()
            self._job = None
        self._end(context)

    def _end(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        if context.workspace is not None:
            context.workspace.status_text_set(None)


class PHYSANIM_OT_free_bake(bpy.types.Operator):
    """Delete PhysAnim bake results and caches (nothing else)"""

    bl_idname = "physanim.free_bake"
    bl_label = "Free PhysAnim Bake"
    bl_options = {'REGISTER', 'UNDO'}

    only_selected: BoolProperty(name="Only Selected", default=False)

    def execute(self, context):
        from ..core.cache import remove_cache

        scene = context.scene
        chosen = {o.name for o in context.selected_objects} if self.only_selected else None
        freed = 0
        try:
            for res in results.result_objects(scene):
                if chosen is None or res.physanim.result.emitter in chosen or res.name in chosen:
                    results.free_result(scene, res)
                    freed += 1
            for ob in scene.objects:  # spring meshes: the cache modifier and its folder
                if chosen is not None and ob.name not in chosen:
                    continue
                folder = springs.cache_folder_of(ob)
                if springs.free(ob):
                    freed += 1
                    if folder:
                        remove_cache(folder)
            rigid = [ob for ob in scene.objects if ob.physanim.rigid_body.baked_action is not None
                     and (chosen is None or ob.name in chosen)]
            for ob in rigid:  # rigid bodies: their keys go, their own animation comes back
                freed += rigid_keys.free_keys(ob)
            if rigid:  # ... and what the bake said of the constraints joining them
                for ob in scene.objects:
                    ob.physanim.constraint.broken_frame = -1
            if rigid and not any(ob.physanim.rigid_body.baked_action is not None
                                 for ob in scene.objects) and bpy.data.filepath:
                remove_cache(cache_paths.rigid_cache_dir(scene))
            for ob in scene.objects:  # followers: their Delta Location keys
                if (chosen is None or ob.name in chosen) and follow.remove_keys(ob):
                    ob.physanim.follow.bake_hash = ""
                    freed += 1
            if freed and bpy.data.filepath:  # a checkpoint of freed frames resumes nothing
                resume.discard(scene)
            # leftovers of results the user deleted by hand: keyed objects and cache folders
            for ob in scene.objects:
                if chosen is not None and ob.name not in chosen:
                    continue
                keyed = results.keyed_collection(scene, ob, create=False)
                if keyed is not None:
                    results.remove_collection(keyed)
                    freed += 1
                if ob.physanim.emitter.enabled and bpy.data.filepath:
                    freed += remove_cache(cache_paths.emitter_cache_dir(scene, ob))
                if ob.physanim.spring_mesh.enabled and bpy.data.filepath:
                    freed += remove_cache(cache_paths.spring_cache_dir(scene, ob))
        except (PhysanimError, OSError) as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        if not results.result_objects(scene) and not any(
                springs.cache_modifier(o) for o in scene.objects if o.type == 'MESH') and not any(
                o.physanim.rigid_body.baked_action is not None for o in scene.objects):
            scene.physanim.bake_hash = ""
            scene.physanim.bake_info = ""
        self.report({'INFO'}, f"freed {freed} bake(s)")
        return {'FINISHED'}


class PHYSANIM_OT_stop_edit(bpy.types.Operator):
    """Add or remove a stop of an emitter's color or size curve"""

    bl_idname = "physanim.stop_edit"
    bl_label = "Edit Curve Stop"
    bl_options = {'REGISTER', 'UNDO'}

    curve: EnumProperty(items=[('COLOR', "Color", ""), ('SIZE', "Size", "")])
    action: EnumProperty(items=[('ADD', "Add", ""), ('REMOVE', "Remove", "")])
    index: IntProperty(default=-1)

    @classmethod
    def poll(cls, context):
        return context.object is not None

    def execute(self, context):
        p = context.object.physanim.emitter
        stops = p.color_stops if self.curve == 'COLOR' else p.size_stops
        if self.action == 'ADD':
            last = stops[len(stops) - 1] if len(stops) else None
            new = stops.add()
            if last is not None:
                new.position = min(1.0, last.position + 0.1) if last.position < 1.0 else 1.0
                new.color, new.value = last.color, last.value
        elif 0 <= self.index < len(stops):
            stops.remove(self.index)
        return {'FINISHED'}


class PHYSANIM_OT_virtual_edit(bpy.types.Operator):
    """Add or remove a group of virtual springs of a spring mesh"""

    bl_idname = "physanim.virtual_edit"
    bl_label = "Edit Virtual Springs"
    bl_options = {'REGISTER', 'UNDO'}

    action: EnumProperty(items=[('ADD', "Add", ""), ('REMOVE', "Remove", "")])
    index: IntProperty(default=-1)

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.type == 'MESH'

    def execute(self, context):
        groups = context.object.physanim.spring_mesh.virtual_springs
        if self.action == 'ADD':
            groups.add()
        elif 0 <= self.index < len(groups):
            groups.remove(self.index)
        return {'FINISHED'}


CLASSES = (PHYSANIM_OT_bake, PHYSANIM_OT_free_bake, PHYSANIM_OT_stop_edit,
           PHYSANIM_OT_virtual_edit)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister() -> None:
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
