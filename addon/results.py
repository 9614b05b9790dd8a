"""Native results of a particle bake: the points object per emitter, refreshed from the cache on
every frame change by a persistent handler, and the optional keyframed-objects output.

The points object carries ``physanim.result.cache`` (a '//'-relative folder of per-frame files).
``frame_change_pre`` and ``load_post`` handlers load the current frame into its mesh, so
scrubbing, headless animation renders and a reloaded .blend all show the right particles.
"""
from __future__ import annotations

import os

import bpy
import numpy as np
from bpy.app.handlers import persistent

from ..core import usd_points
from ..core.cache import read_frame
from ..core.errors import PhysanimError
from . import compat, instancing, native_points, points, render_modes

MAX_KEYED_OBJECTS = 20_000  # the Objects output makes one Blender object per particle
EMPTY = {"position": np.zeros((0, 3), np.float32)}
KEYED_TAG = "physanim_keyed_objects"  # custom property naming the emitter of a keyed collection

# Scenes being baked right now: their frame changes are the bake's own sampling, so results are
# not reloaded (that would read the previous bake on every sample). UI state, not sim state.
_baking: set[str] = set()


def suspend_refresh(scene) -> None:
    _baking.add(scene.name)


def resume_refresh(scene) -> None:
    _baking.discard(scene.name)


def cache_folder(res) -> str:
    """Absolute folder of a result's cache ('//' resolves against the result's own .blend)."""
    path = res.physanim.result.cache
    return bpy.path.abspath(path, library=res.library) if path else ""


def _collection_of(ob, scene):
    return ob.users_collection[0] if ob.users_collection else scene.collection


def _result_object(scene, emitter_ob, kind: str):
    """The emitter's result object, of type ``kind`` ('MESH' or 'POINTCLOUD'): a result of the
    other type (the output was switched) is replaced by one of the same name and collections."""
    p = emitter_ob.physanim.emitter
    res = p.result
    if res is not None and res.name in bpy.data.objects and res.type == kind:
        return res
    name, collections = f"{emitter_ob.name}_particles", None
    if res is not None and res.name in bpy.data.objects:
        name, collections = res.name, list(res.users_collection)
        _remove_object(res)
    if kind == 'POINTCLOUD':
        data = bpy.data.pointclouds.new(name)
    else:
        data = bpy.data.meshes.new(name)
    res = bpy.data.objects.new(name, data)
    for coll in collections or [_collection_of(emitter_ob, scene)]:
        coll.objects.link(res)
    p.result = res
    return res


def _remove_object(res) -> None:
    """Delete a result object and its data (not its cache)."""
    native_points.remove_reader(res)
    data = res.data
    bpy.data.objects.remove(res)
    if data is not None and data.users == 0:
        (bpy.data.pointclouds if isinstance(data, bpy.types.PointCloud)
         else bpy.data.meshes).remove(data)


def attach(context, scene, emitter_ob, cache_rel: str, frame_start: int, frame_end: int,
           inputs_hash: str = "") -> None:
    """Point the emitter's result object at a finished bake and build its output."""
    p = emitter_ob.physanim.emitter
    native = p.output == 'USD_POINTS'
    res = _result_object(scene, emitter_ob, 'POINTCLOUD' if native else 'MESH')
    res.physanim.result.cache = cache_rel
    res.physanim.result.emitter = emitter_ob.name
    res.physanim.result.hash = inputs_hash
    instance = p.instance_object or instancing.default_particle_object()
    if native:
        _attach_usd(res, cache_rel, frame_start, frame_end)
    render_modes.apply(res, p)
    keyed = keyed_collection(scene, emitter_ob, create=False)
    if p.output == 'OBJECTS':
        write_keyed_objects(scene, emitter_ob, cache_rel, frame_start, frame_end, instance)
        res.hide_render = True  # the keyed objects render; the points stay for scripts
    else:
        if keyed is not None:
            remove_collection(keyed)
        res.hide_render = False
    if not native:
        refresh(res, scene.frame_current)


def _attach_usd(res, cache_rel: str, frame_start: int, frame_end: int) -> None:
    """Point a point cloud result at the bake's USD frames (``usd/`` beside the npz stream)."""
    folder = os.path.dirname(bpy.path.abspath(cache_rel).rstrip("/\\"))
    usd_dir = os.path.join(folder, native_points.STREAM)
    files = sorted(os.listdir(usd_dir)) if os.path.isdir(usd_dir) else []
    first = read_frame(bpy.path.abspath(cache_rel), frame_start)
    if not files or first is None:
        raise PhysanimError(f'the bake has no USD point files in "{usd_dir}"',
                            obj=res.physanim.result.emitter, frame=frame_start, kind="emitter")
    layout = usd_points.attribute_layout(first)
    rel = cache_rel.rstrip("/").rsplit("/", 1)[0] + f"/{native_points.STREAM}/{files[0]}"
    native_points.ensure_reader(res, rel, layout, frame_start, frame_end)


def refresh(res, frame: int) -> None:
    """Load ``frame`` of a result's cache into its points mesh (empty outside the bake)."""
    folder = cache_folder(res)
    arrays = read_frame(folder, frame) if folder else None
    points.write_points(res.data, arrays if arrays is not None else EMPTY)


def refresh_scene(scene) -> None:
    for ob in scene.objects:
        if ob.type == 'MESH' and ob.physanim.result.cache:
            try:
                refresh(ob, scene.frame_current)
            except (OSError, ValueError) as exc:  # a broken cache must not break playback
                print(f'PhysAnim: cannot load "{ob.name}" at frame {scene.frame_current}: {exc}')


@persistent
def on_frame_change(scene, depsgraph=None) -> None:
    if scene.name not in _baking:
        refresh_scene(scene)


@persistent
def on_load_post(*_args) -> None:
    for scene in bpy.data.scenes:
        refresh_scene(scene)


# --- keyframed objects output -------------------------------------------------------------------

def keyed_collection(scene, emitter_ob, create: bool):
    """The collection of keyed particle objects a bake made for ``emitter_ob`` — found by its
    tag, never by name, so a user's collection of the same name is never touched."""
    name = emitter_ob.name if emitter_ob is not None else None
    for coll in bpy.data.collections:
        if coll.get(KEYED_TAG) == name and coll.library is None:
            return coll
    if not create:
        return None
    coll = bpy.data.collections.new(f"{emitter_ob.name}_particle_objects")
    coll[KEYED_TAG] = emitter_ob.name
    _collection_of(emitter_ob, scene).children.link(coll)
    return coll


def remove_collection(coll) -> None:
    for ob in list(coll.objects):
        ad = ob.animation_data
        action = ad.action if ad else None
        bpy.data.objects.remove(ob)
        if action is not None and action.users == 0:
            bpy.data.actions.remove(action)
    bpy.data.collections.remove(coll)


def _tracks(folder: str, frame_start: int, frame_end: int):
    """Every cached frame concatenated: (frame, id, position, size, color), sorted by id."""
    parts = []
    for f in range(frame_start, frame_end + 1):
        a = read_frame(folder, f)
        if a is None or len(a["id"]) == 0:
            continue
        parts.append((np.full(len(a["id"]), f, np.int64), a["id"].astype(np.int64),
                      a["position"], a["size"], a["color"]))
    if not parts:
        return None
    frames, ids, pos, size, color = (np.concatenate(c) for c in zip(*parts))
    order = np.lexsort((frames, ids))
    return frames[order], ids[order], pos[order], size[order], color[order]


def write_keyed_objects(scene, emitter_ob, cache_rel: str, frame_start: int, frame_end: int,
                        instance) -> int:
    """One linked duplicate of ``instance`` per particle, keyed on location, scale (0 outside its
    life) and color, written in bulk per F-curve. Returns the number of objects."""
    tracks = _tracks(bpy.path.abspath(cache_rel), frame_start, frame_end)
    old = keyed_collection(scene, emitter_ob, create=False)
    if old is not None:
        remove_collection(old)
    if tracks is None:
        return 0
    frames, ids, pos, size, color = tracks
    uniq, starts = np.unique(ids, return_index=True)
    if len(uniq) > MAX_KEYED_OBJECTS:
        raise PhysanimError(f"{len(uniq):,} particles are too many for the Objects output "
                            f"(limit {MAX_KEYED_OBJECTS:,}) — use the Points output",
                            obj=emitter_ob.name, frame=frame_end, kind="emitter")
    coll = keyed_collection(scene, emitter_ob, create=True)
    bounds = np.append(starts, len(ids))
    for k, pid in enumerate(uniq):
        lo, hi = bounds[k], bounds[k + 1]
        ob = bpy.data.objects.new(f"{emitter_ob.name}_p{int(pid)}", instance.data)
        coll.objects.link(ob)
        bag = compat.channelbag_for(ob)
        f = frames[lo:hi].astype(np.float32)
        for axis in range(3):
            compat.set_keys(compat.fcurve_ensure(bag, "location", axis), f, pos[lo:hi, axis])
            compat.set_keys(compat.fcurve_ensure(bag, "color", axis), f, color[lo:hi, axis])
        compat.set_keys(compat.fcurve_ensure(bag, "color", 3), f, color[lo:hi, 3])
        # scale: 0 before birth and after death, stepping (CONSTANT) at both ends
        sf = np.concatenate([[f[0] - 1.0], f, [f[-1] + 1.0]])
        sv = np.concatenate([[0.0], size[lo:hi], [0.0]])
        for axis in range(3):
            fc = compat.fcurve_ensure(bag, "scale", axis)
            compat.set_keys(fc, sf, sv, interpolation='LINEAR')
            kp = fc.keyframe_points
            kp[0].interpolation = 'CONSTANT'
            kp[len(kp) - 2].interpolation = 'CONSTANT'
    return len(uniq)


# --- free bake ---------------------------------------------------------------------------------

def result_objects(scene) -> list:
    """Every bake result in ``scene`` (whether or not its emitter still exists or is enabled)."""
    return [ob for ob in scene.objects
            if ob.type in ('MESH', 'POINTCLOUD') and ob.physanim.result.cache]


def free_result(scene, res) -> None:
    """Remove one result: its cache folder, its keyed objects and actions, the object and mesh."""
    from ..core.cache import remove_cache

    folder = cache_folder(res)
    if folder:
        remove_cache(os.path.dirname(os.path.normpath(folder)))
    emitter_name = res.physanim.result.emitter
    emitter = bpy.data.objects.get(emitter_name)
    keyed = keyed_collection(scene, emitter, create=False) if emitter is not None else None
    if keyed is None:
        keyed = next((c for c in bpy.data.collections if c.get(KEYED_TAG) == emitter_name), None)
    if keyed is not None:
        remove_collection(keyed)
    if emitter is not None and emitter.physanim.emitter.result == res:
        emitter.physanim.emitter.result = None
    _remove_object(res)
    instancing.remove_unused()
    native_points.remove_unused()


HANDLERS = (("frame_change_pre", on_frame_change), ("load_post", on_load_post))


def register() -> None:
    for name, fn in HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        if fn not in handlers:
            handlers.append(fn)


def unregister() -> None:
    for name, fn in HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        while fn in handlers:
            handlers.remove(fn)
