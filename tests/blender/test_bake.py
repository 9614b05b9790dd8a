"""The particle bake seen from Blender: operators, result points, cache, determinism, keyframed
inputs, freeing, the Objects output, only-selected bakes, moving emitters and colliders, and
rendering the result headless.

Scenes are tiny (tens of particles, about a dozen frames) so the whole file runs in seconds.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Vector

from sample_scenes._common import result_points

ATTRIBUTE_TYPES = {"id": 'INT', "age": 'FLOAT', "velocity": 'FLOAT_VECTOR', "size": 'FLOAT',
                   "color": 'FLOAT_COLOR'}
_READ = {'INT': ("value", 1, np.int32), 'FLOAT': ("value", 1, np.float32),
         'FLOAT_VECTOR': ("vector", 3, np.float32), 'FLOAT_COLOR': ("color", 4, np.float32)}


# ------------------------------------------------------------------------------------- helpers

def _addon(ext, name: str):
    return sys.modules[f"{ext.__name__}.addon.{name}"]


def _core_cache(ext):
    return sys.modules[f"{ext.__name__}.core.cache"]


def _setup(frame_end: int = 12, substeps: int = 2, gravity: bool = True):
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, frame_end
    scene.physanim.frame_start, scene.physanim.frame_end = 1, frame_end
    scene.physanim.substeps = substeps
    scene.use_gravity = gravity
    scene.render.fps, scene.render.fps_base = 24, 1.0
    return scene


def _emitter(name: str, location=(0.0, 0.0, 0.0), **props) -> bpy.types.Object:
    ob = bpy.data.objects.new(name, None)
    bpy.context.scene.collection.objects.link(ob)
    ob.location = location
    p = ob.physanim.emitter
    p.enabled = True
    values = dict(rate=6.0, lifetime=4.0, lifetime_random=1.5, speed=2.0, spread=0.5)
    values.update(props)
    for key, value in values.items():
        setattr(p, key, value)
    return ob


def _save(tmp_path: Path, name: str = "scene.blend") -> Path:
    path = tmp_path / name
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def _stream(ob) -> Path:
    """Absolute folder of an emitter's per-frame point files."""
    return Path(bpy.path.abspath(ob.physanim.emitter.result.physanim.result.cache))


def _cached(ext, ob, frame: int) -> dict[str, np.ndarray]:
    arrays = _core_cache(ext).read_frame(_stream(ob), frame)
    assert arrays is not None, f"frame {frame} of {ob.name} is not in the cache"
    return arrays


def _result_points(ob) -> dict[str, np.ndarray]:
    """The result object's points and attributes, as Blender shows them now (before the
    instancing modifier)."""
    return result_points(ob.physanim.emitter.result)


def _shown_types(ob) -> dict[str, tuple[str, str]]:
    """Attribute name -> (data type, domain) of the result's geometry before instancing."""
    res = ob.physanim.emitter.result
    instancer = res.modifiers["physanim_instances"]
    instancer.show_viewport = False
    try:
        data = res.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
        return {a.name: (a.data_type, a.domain) for a in data.attributes}
    finally:
        instancer.show_viewport = True


def _assert_shows_frame(ext, ob, frame: int) -> None:
    """The result object holds exactly the cached particles of ``frame``."""
    shown, cached = _result_points(ob), _cached(ext, ob, frame)
    assert len(shown["position"]) == len(cached["id"]), f"{ob.name} at frame {frame}"
    if not len(cached["id"]):
        return
    np.testing.assert_array_equal(shown["id"], cached["id"])
    np.testing.assert_array_equal(shown["position"], cached["position"])
    for name in ("age", "velocity", "size", "color"):
        np.testing.assert_array_equal(shown[name], cached[name], err_msg=f"{name} at {frame}")


def _cache_arrays(folder: Path) -> dict[str, bytes]:
    """Every array of every frame file below ``folder``: {file/key: bytes}."""
    out = {}
    for path in sorted(folder.rglob("*.npz")):
        with np.load(path, allow_pickle=False) as data:
            for key in data.files:
                out[f"{path.relative_to(folder)}/{key}"] = data[key].tobytes() + str(
                    (data[key].dtype, data[key].shape)).encode()
    return out


def _file_bytes(folder: Path) -> dict[str, tuple[bytes, int]]:
    return {str(p.relative_to(folder)): (p.read_bytes(), p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _linear_keys(ob, data_path: str, keys, index: int = -1) -> None:
    """Keyframe ``ob.<data_path>`` at (frame, value) pairs, with linear interpolation."""
    owner_path, _, attr = data_path.rpartition(".")
    owner = ob.path_resolve(owner_path) if owner_path else ob
    for frame, value in keys:
        if index >= 0:
            getattr(owner, attr)[index] = value
        else:
            setattr(owner, attr, value)
        ob.keyframe_insert(data_path, index=index, frame=frame)
    curves = _fcurves(ob)
    for curve in curves:
        for point in curve.keyframe_points:
            point.interpolation = 'LINEAR'
        curve.update()


def _fcurves(ob):
    ad = ob.animation_data
    action = ad.action
    if hasattr(bpy.types, "ActionSlot"):  # 4.4+: curves live in the slot's channelbag
        curves = []
        for layer in action.layers:
            for strip in layer.strips:
                bag = strip.channelbag(ad.action_slot)
                if bag is not None:
                    curves.extend(bag.fcurves)
        return curves
    return list(action.fcurves)


# ---------------------------------------------------------------------- result and cache

@pytest.mark.parametrize("output, kind", [('USD_POINTS', 'POINTCLOUD'), ('POINTS', 'MESH')])
def test_result_holds_exactly_the_particles_alive_at_each_frame(physanim_ext, tmp_path, output,
                                                                kind):
    """Both Points outputs: USD files read by Blender's modifiers, and the extension's mesh."""
    scene = _setup(frame_end=12)
    a = _emitter("A", seed=1, output=output)
    b = _emitter("B", location=(3.0, 0.0, 0.0), seed=2, rate=4.0, output=output)
    _save(tmp_path)

    assert bpy.ops.physanim.bake() == {'FINISHED'}

    for ob in (a, b):
        res = ob.physanim.emitter.result
        assert res is not None and res.type == kind and res.name in scene.objects
        # the bake goes back to the frame it started from and shows that frame
        _assert_shows_frame(physanim_ext, ob, scene.frame_current)
    for frame in (6, 12, 3, 1, 9, 2, 12, 7):  # scrubbing backwards and forwards
        scene.frame_set(frame)
        for ob in (a, b):
            _assert_shows_frame(physanim_ext, ob, frame)
    scene.frame_set(8)
    attributes = _shown_types(a)
    for name, data_type in ATTRIBUTE_TYPES.items():
        assert attributes[name] == (data_type, 'POINT')
    assert len(_result_points(a)["position"]) > 5

    # ids: unique across the bake (both emitters), each alive over one unbroken run of frames
    lives: dict[int, list[int]] = {}
    owner: dict[int, str] = {}
    for ob in (a, b):
        for frame in range(1, 13):
            ids = _cached(physanim_ext, ob, frame)["id"]
            assert len(np.unique(ids)) == len(ids)
            for pid in ids.tolist():
                assert owner.setdefault(pid, ob.name) == ob.name, f"id {pid} used by A and B"
                lives.setdefault(pid, []).append(frame)
    for pid, frames in lives.items():
        assert frames == list(range(frames[0], frames[-1] + 1)), f"id {pid} reappears: {frames}"
    assert any(f[-1] < 12 for f in lives.values()), "no particle died: lifetimes not applied"
    # age in frames: +1 per frame; never reaching the (frames) lifetime
    for frame in range(1, 12):
        now, nxt = _cached(physanim_ext, a, frame), _cached(physanim_ext, a, frame + 1)
        _, i, j = np.intersect1d(now["id"], nxt["id"], return_indices=True)
        np.testing.assert_allclose(nxt["age"][j] - now["age"][i], 1.0, atol=1e-4)
        assert (nxt["age"] < 4.0 + 1.5 + 1e-4).all()

    # outside the baked range the result is empty
    for frame in (40, 0):
        scene.frame_set(frame)
        assert len(_result_points(a)["position"]) == 0


def test_velocity_is_in_metres_per_second(physanim_ext, tmp_path):
    scene = _setup(frame_end=8, gravity=False)
    ob = _emitter("E", speed=3.0, spread=0.8, lifetime=50.0)
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    now, nxt = _cached(physanim_ext, ob, 5), _cached(physanim_ext, ob, 6)
    common, i, j = np.intersect1d(now["id"], nxt["id"], return_indices=True)
    assert len(common) > 5
    fps = scene.render.fps / scene.render.fps_base
    displacement_per_s = (nxt["position"][j] - now["position"][i]) * fps
    np.testing.assert_allclose(displacement_per_s, now["velocity"][i], atol=1e-4)
    np.testing.assert_allclose(np.linalg.norm(now["velocity"], axis=1), 3.0, rtol=1e-5)


def test_result_follows_frames_after_save_and_reload(physanim_ext, tmp_path):
    scene = _setup(frame_end=10)
    _emitter("Nozzle")
    path = _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    bpy.ops.wm.save_mainfile()

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.wm.open_mainfile(filepath=str(path))
    scene = bpy.context.scene
    ob = scene.objects["Nozzle"]
    assert ob.physanim.emitter.result.physanim.result.cache.startswith("//")
    for frame in (4, 9, 2, 10):
        scene.frame_set(frame)
        _assert_shows_frame(physanim_ext, ob, frame)
        assert len(_result_points(ob)["position"]) > 0


def test_headless_animation_render_shows_the_particles(physanim_ext, tmp_path):
    scene = _setup(frame_end=6)
    ob = _emitter("Spray", rate=3.0, speed=6.0, spread=0.3, size=0.35, lifetime=40.0)
    for stop in ob.physanim.emitter.color_stops:
        stop.color = (1.0, 0.2, 0.1, 1.0)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    camera.location = (0.0, -8.0, 0.5)
    camera.rotation_euler = (math.pi / 2, 0.0, 0.0)
    scene.camera = camera
    render = scene.render
    render.engine = 'BLENDER_WORKBENCH'
    render.resolution_x, render.resolution_y, render.resolution_percentage = 64, 48, 100
    render.film_transparent = True
    render.image_settings.file_format = 'PNG'
    render.image_settings.color_mode = 'RGBA'
    scene.frame_start, scene.frame_end = 3, 5
    render.filepath = str(tmp_path / "render" / "f_####")
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}

    bpy.ops.render.render(animation=True)

    frames = {}
    for frame in (3, 4, 5):
        path = tmp_path / "render" / f"f_{frame:04d}.png"
        assert path.is_file(), f"frame {frame} was not written"
        image = bpy.data.images.load(str(path))
        pixels = np.empty(image.size[0] * image.size[1] * 4, np.float32)
        image.pixels.foreach_get(pixels)
        frames[frame] = pixels.reshape(image.size[1], image.size[0], 4)
        bpy.data.images.remove(image)
        alpha = frames[frame][..., 3]
        assert 0 < (alpha > 0.5).mean() < 0.5, f"frame {frame}: no particles (or a filled frame)"
        # every cached particle in view is drawn where it is at that frame
        drawn = 0
        for position in _cached(physanim_ext, ob, frame)["position"]:
            u, v, depth = world_to_camera_view(scene, camera, Vector(position.tolist()))
            if depth > 0 and 0.02 < u < 0.98 and 0.02 < v < 0.98:
                assert alpha[int(v * alpha.shape[0]), int(u * alpha.shape[1])] > 0.5
                drawn += 1
        assert drawn > 0
    assert np.abs(frames[3][..., 3] - frames[4][..., 3]).max() > 0.5
    assert np.abs(frames[4][..., 3] - frames[5][..., 3]).max() > 0.5


# --------------------------------------------------------------------------- determinism

def test_bake_is_deterministic_and_hashed(physanim_ext, tmp_path):
    scene = _setup(frame_end=10)
    a = _emitter("A", rate=5.0, rate_random=3.0, speed_random=1.0, seed=4)
    _emitter("B", location=(1.0, 0.0, 0.0), rate=2.0, seed=9)
    _save(tmp_path)
    panels = _addon(physanim_ext, "panels")
    assert panels.bake_status(scene)[0] == "Not baked"

    assert bpy.ops.physanim.bake() == {'FINISHED'}
    root = Path(bpy.path.abspath(scene.physanim.cache_dir))
    first = _cache_arrays(root)
    assert len(first) > 20
    meta = json.loads((_stream(a).parent / "meta.json").read_text())
    assert len(scene.physanim.bake_hash) >= 32
    assert len(meta["hash"]) >= 32 and meta["hash"] == a.physanim.emitter.result.physanim.result.hash
    assert panels.bake_status(scene)[1] == 'CHECKMARK'

    assert bpy.ops.physanim.bake() == {'FINISHED'}
    second = _cache_arrays(root)
    assert first.keys() == second.keys()
    assert all(first[k] == second[k] for k in first), "a re-bake changed the cache"
    assert json.loads((_stream(a).parent / "meta.json").read_text())["hash"] == meta["hash"]

    a.physanim.emitter.rate = 5.5
    text, icon = panels.bake_status(scene)
    assert icon == 'ERROR' and "outdated" in text and text.endswith(": A")
    a.physanim.emitter.rate = 5.0
    assert panels.bake_status(scene)[1] == 'CHECKMARK'
    scene.physanim.seed = 1  # a new seed changes the cache (the comparison above has teeth)
    assert panels.bake_status(scene)[1] == 'ERROR'
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert _cache_arrays(root) != first


# ---------------------------------------------------------------- keyframed emitter inputs

def test_keyframed_rate_is_sampled_per_frame(physanim_ext, tmp_path):
    _setup(frame_end=12)
    ob = _emitter("Ramp", lifetime=100.0, lifetime_random=0.0)
    _linear_keys(ob, "physanim.emitter.rate", [(1, 0.0), (10, 90.0)])
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}

    previous = set()
    for frame in range(1, 13):
        ids = set(_cached(physanim_ext, ob, frame)["id"].tolist())
        assert previous <= ids  # nothing dies
        born = len(ids - previous)
        rate = 10.0 * min(frame - 1, 9)  # births shown at frame f use the rate at frame f
        assert math.floor(rate) <= born <= math.ceil(rate) + 1e-9, (frame, born, rate)
        previous = ids
    assert len(previous) > 300


def test_emitter_frame_range_limits_births(physanim_ext, tmp_path):
    _setup(frame_end=12)
    ob = _emitter("Window", rate=5.0, lifetime=100.0, lifetime_random=0.0)
    ob.physanim.emitter.frame_start, ob.physanim.emitter.frame_end = 4, 7
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    counts = [len(_cached(physanim_ext, ob, f)["id"]) for f in range(1, 13)]
    # inclusive window: births show at frames 4, 5, 6 and 7 (those of frame f happen in [f-1, f])
    assert counts == [0, 0, 0, 5, 10, 15, 20, 20, 20, 20, 20, 20]


def test_keyframed_frame_start_is_sampled_per_frame(physanim_ext, tmp_path):
    _setup(frame_end=10)
    ob = _emitter("Late", rate=4.0, lifetime=100.0, lifetime_random=0.0)
    ob.physanim.emitter.frame_start = 1
    ob.keyframe_insert("physanim.emitter.frame_start", frame=1)
    ob.physanim.emitter.frame_start = 6
    ob.keyframe_insert("physanim.emitter.frame_start", frame=2)
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    counts = [len(_cached(physanim_ext, ob, f)["id"]) for f in range(1, 11)]
    # frame 1 gives births (start 1: they happen in [0, 1], before the bake, and show at
    # frame 1), then none until frame 6 (start keyed to 6 from frame 2 on)
    assert counts == [4, 4, 4, 4, 4, 8, 12, 16, 20, 24]


# ---------------------------------------------------------------------------------- free

def _data_names() -> dict[str, set[str]]:
    return {kind: {item.name for item in getattr(bpy.data, kind)} for kind in (
        "objects", "meshes", "materials", "node_groups", "collections", "actions", "images")}


def test_free_bake_removes_only_what_the_bake_made(physanim_ext, tmp_path):
    scene = _setup(frame_end=6)
    points_emitter = _emitter("Points", rate=3.0)
    keyed_emitter = _emitter("Keyed", location=(2.0, 0.0, 0.0), rate=1.0, output='OBJECTS')
    user_mesh = bpy.data.meshes.new("UserMesh")
    user = bpy.data.objects.new("UserObject", user_mesh)
    scene.collection.objects.link(user)
    bpy.data.materials.new("UserMaterial")
    user_collection = bpy.data.collections.new("UserCollection")
    scene.collection.children.link(user_collection)
    user.keyframe_insert("location", frame=1)
    _save(tmp_path)
    before = _data_names()
    settings = {ob.name: {k: getattr(ob.physanim.emitter, k) for k in (
        "enabled", "rate", "lifetime", "speed", "output")} for ob in (points_emitter, keyed_emitter)}
    root = Path(bpy.path.abspath(scene.physanim.cache_dir))
    root.mkdir()
    (root / "notes.txt").write_text("mine")

    assert bpy.ops.physanim.bake() == {'FINISHED'}
    made = {k: v - before[k] for k, v in _data_names().items()}
    assert {"Points_particles", "Keyed_particles"} <= made["objects"]
    assert "Keyed_particle_objects" in made["collections"]
    assert len(made["actions"]) >= 1
    folders = [_stream(ob).parent for ob in (points_emitter, keyed_emitter)]
    assert all(f.is_dir() for f in folders)

    assert bpy.ops.physanim.free_bake() == {'FINISHED'}

    assert _data_names() == before  # every bake data-block gone, nothing else touched
    assert not any(f.exists() for f in folders)
    assert (root / "notes.txt").read_text() == "mine"
    assert not [p for p in root.rglob("*") if p.is_file() and p.name != "notes.txt"]
    for ob in (points_emitter, keyed_emitter):
        assert ob.physanim.emitter.result is None
        assert {k: getattr(ob.physanim.emitter, k) for k in settings[ob.name]} == settings[ob.name]
    assert user.animation_data.action is not None and user.data == user_mesh
    assert scene.physanim.bake_hash == ""
    scene.frame_set(3)  # playback without results does not fail
    # and the scene bakes again
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert points_emitter.physanim.emitter.result is not None


# -------------------------------------------------------------------------- objects output

def test_objects_output_keys_one_object_per_particle(physanim_ext, tmp_path):
    scene = _setup(frame_end=8)
    ob = _emitter("Few", rate=2.0, lifetime=3.0, lifetime_random=1.0, output='OBJECTS')
    stops = ob.physanim.emitter.color_stops
    stops[0].color, stops[1].color = (1.0, 0.0, 0.0, 1.0), (0.0, 0.0, 1.0, 0.5)
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}

    collection = bpy.data.collections["Few_particle_objects"]
    cached = {f: _cached(physanim_ext, ob, f) for f in range(1, 9)}
    ids = np.unique(np.concatenate([c["id"] for c in cached.values()]))
    assert len(ids) >= 8
    objects = {o.name: o for o in collection.objects}
    assert set(objects) == {f"Few_p{pid}" for pid in ids.tolist()}
    assert ob.physanim.emitter.result.hide_render  # the keyed objects render, not the points
    seen_zero_before = seen_zero_after = False
    for frame in (1, 2, 3, 4, 5, 6, 7, 8, 9):
        scene.frame_set(frame)
        alive = cached.get(frame, {"id": np.zeros(0, np.int32)})
        index = {int(pid): k for k, pid in enumerate(alive["id"])}
        for pid in ids.tolist():
            particle = objects[f"Few_p{pid}"]
            if pid in index:
                k = index[pid]
                np.testing.assert_allclose(particle.location, alive["position"][k], atol=1e-5)
                np.testing.assert_allclose(particle.scale, [alive["size"][k]] * 3, rtol=1e-5)
                np.testing.assert_allclose(particle.color, alive["color"][k], atol=1e-5)
                assert particle.scale[0] > 0
            else:
                assert tuple(particle.scale) == (0.0, 0.0, 0.0), (pid, frame)
                born_later = any(pid in c["id"] for f, c in cached.items() if f > frame)
                seen_zero_before |= born_later
                seen_zero_after |= not born_later
    assert seen_zero_before and seen_zero_after


# ---------------------------------------------------------------------------- only selected

def test_only_selected_keeps_the_other_emitters_cache(physanim_ext, tmp_path):
    scene = _setup(frame_end=8)
    a = _emitter("A", seed=1)
    b = _emitter("B", location=(2.0, 0.0, 0.0), seed=2)
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    b_files = _file_bytes(_stream(b).parent)
    a_arrays = _cache_arrays(_stream(a).parent)
    b_result = b.physanim.emitter.result
    scene.frame_set(5)
    b_points = _result_points(b)

    a.physanim.emitter.rate = b.physanim.emitter.rate = 9.0  # both would change if re-baked
    for o in scene.objects:
        o.select_set(False)
    a.select_set(True)
    assert bpy.ops.physanim.bake(only_selected=True) == {'FINISHED'}

    assert _file_bytes(_stream(b).parent) == b_files
    assert _cache_arrays(_stream(a).parent) != a_arrays
    assert b.physanim.emitter.result == b_result
    scene.frame_set(5)
    after = _result_points(b)
    assert all(np.array_equal(after[k], b_points[k]) for k in b_points)
    _assert_shows_frame(physanim_ext, a, 5)


# ---------------------------------------------------------------------- motion of the scene

def test_moving_emitter_passes_on_its_velocity(physanim_ext, tmp_path):
    scene = _setup(frame_end=12, gravity=False)
    ob = _emitter("Thrower", rate=4.0, speed=0.0, lifetime=100.0, inherit_velocity=0.5)
    _linear_keys(ob, "location", [(1, 0.0), (13, 6.0)], index=0)
    _linear_keys(ob, "location", [(1, 0.0), (13, 3.0)], index=1)
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    fps = scene.render.fps / scene.render.fps_base
    emitter_velocity = np.array([6.0, 3.0, 0.0]) / 12.0 * fps  # (12, 6, 0) m/s
    for frame in (4, 8, 12):
        arrays = _cached(physanim_ext, ob, frame)
        young = arrays["age"] < 1.0
        assert young.any()
        np.testing.assert_allclose(arrays["velocity"][young], np.broadcast_to(
            0.5 * emitter_velocity, (young.sum(), 3)), atol=1e-3)
        # born on the emitter's path, then carried at half its speed
        scene.frame_set(frame)
        here = np.array(ob.matrix_world.translation)
        expected = here - 0.5 * emitter_velocity * (arrays["age"][young, None] / fps)
        np.testing.assert_allclose(arrays["position"][young], expected, atol=1e-3)


def test_particles_ride_a_rising_animated_ground(physanim_ext, tmp_path):
    scene = _setup(frame_end=24, substeps=4)
    _emitter("Drop", location=(0.0, 0.0, 0.1), rate=5.0, speed=0.0, frame_end=3,
             lifetime=100.0, lifetime_random=0.0)
    ground = bpy.data.objects.new("Lift", None)
    scene.collection.objects.link(ground)
    ground.physanim.collider.enabled = True
    ground.physanim.collider.shape = 'HALF_SPACE'
    ground.physanim.collider.restitution = 0.0
    ground.physanim.collider.friction = 0.5
    _linear_keys(ground, "location", [(1, 0.0), (8, 0.0), (20, 0.6), (24, 0.6)], index=2)
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}

    def ground_z(frame):
        return float(np.interp(frame, [1, 8, 20, 24], [0.0, 0.0, 0.6, 0.6]))

    drop = scene.objects["Drop"]
    for frame in range(6, 25):
        z = _cached(physanim_ext, drop, frame)["position"][:, 2]
        assert len(z) == 15  # frames 1-3 at 5 births each
        assert z.min() >= ground_z(frame) - 2e-3, (frame, z.min(), ground_z(frame))
        if 8 <= frame <= 20:  # riding the ground (afterwards they may hop off as it stops)
            np.testing.assert_allclose(z, ground_z(frame), atol=0.03, err_msg=f"frame {frame}")


def test_bake_status_ignores_scrubbing_but_sees_animation_and_parent_edits(physanim_ext, tmp_path):
    """The outdated check must not depend on the current frame, and must see keyframe edits of
    an emitter's animated parent; an only-selected bake leaves the others' status alone."""
    scene = _setup(frame_end=6)
    parent = bpy.data.objects.new("Rig", None)
    scene.collection.objects.link(parent)
    for frame, x in ((1, 0.0), (6, 3.0)):
        parent.location.x = x
        parent.keyframe_insert("location", index=0, frame=frame)
    a = _emitter("A", rate=4.0)
    a.parent = parent
    for frame, rate in ((1, 4.0), (6, 8.0)):
        a.physanim.emitter.rate = rate
        a.keyframe_insert("physanim.emitter.rate", frame=frame)
    b = _emitter("B", location=(2.0, 0.0, 0.0), rate=2.0)
    _save(tmp_path)
    panels = _addon(physanim_ext, "panels")
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    for frame in (1, 3, 6):
        scene.frame_set(frame)
        assert panels.bake_status(scene)[1] == 'CHECKMARK', f"frame {frame}"
    compat = _addon(physanim_ext, "compat")
    curve = compat.action_fcurves(parent.animation_data)[0]
    curve.keyframe_points[1].co.y = 5.0
    text, icon = panels.bake_status(scene)
    assert icon == 'ERROR' and text.endswith(": A")
    for ob in scene.objects:
        ob.select_set(ob == a)
    assert bpy.ops.physanim.bake(only_selected=True) == {'FINISHED'}
    assert panels.bake_status(scene)[1] == 'CHECKMARK'
    b.physanim.emitter.rate = 3.0
    text, icon = panels.bake_status(scene)
    assert icon == 'ERROR' and text.endswith(": B")


def test_free_bake_finds_results_of_disabled_emitters_and_spares_user_collections(
        physanim_ext, tmp_path):
    scene = _setup(frame_end=4)
    a = _emitter("A", rate=3.0)
    a.physanim.emitter.output = 'OBJECTS'
    b = _emitter("B", rate=3.0)
    mine = bpy.data.collections.new("B_particle_objects")  # the name a bake would derive
    scene.collection.children.link(mine)
    precious = bpy.data.objects.new("Precious", None)
    mine.objects.link(precious)
    _save(tmp_path)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert "Precious" in bpy.data.objects and "B_particle_objects" in bpy.data.collections
    keyed = [c for c in bpy.data.collections if c.get("physanim_keyed_objects") == "A"]
    assert len(keyed) == 1 and len(keyed[0].objects) > 0
    folders = [_stream(a).parent, _stream(b).parent]
    assert all(f.is_dir() for f in folders)
    a.physanim.emitter.enabled = False  # switched off after baking: its bake must still go
    assert bpy.ops.physanim.free_bake() == {'FINISHED'}
    assert not any(f.exists() for f in folders)
    assert not [c for c in bpy.data.collections if c.get("physanim_keyed_objects")]
    assert a.physanim.emitter.result is None and b.physanim.emitter.result is None
    assert "Precious" in bpy.data.objects and "B_particle_objects" in bpy.data.collections
    assert scene.physanim.bake_hash == ""
