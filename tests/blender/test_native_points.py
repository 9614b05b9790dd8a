"""The Points output plays and renders without the extension: USD files per frame, read by
Blender's own Mesh Sequence Cache modifier and Geometry Nodes (see ``addon/native_points.py``).

The decisive test renders a baked file in a fresh process in which PhysAnim was never installed
and compares its pixels with the render of the same file where PhysAnim is enabled, and with the
render of the extension's own Points output.
"""
from __future__ import annotations

import math
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import bpy
import numpy as np
import pytest

from physanim.tests.blender.probes import LabelRecorder, image_pixels, render_still
from sample_scenes._common import result_points

NATIVE_MODIFIERS = [("physanim_cache", 'MESH_SEQUENCE_CACHE'), ("physanim_attributes", 'NODES'),
                    ("physanim_instances", 'NODES')]


def _scene(tmp_path: Path, frame_end: int = 12):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    scene.physanim.frame_start, scene.physanim.frame_end = 1, frame_end
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "shot.blend"))
    return scene


def _default_emitter(scene):
    """An emitter with nothing set but its switch: a plane, as a user adds one."""
    bpy.ops.mesh.primitive_plane_add(size=2.0)
    ob = bpy.context.object
    ob.physanim.emitter.enabled = True
    return ob


def _addon(ext, name: str):
    return sys.modules[f"{ext.__name__}.addon.{name}"]


def test_points_at_the_defaults_are_read_by_native_modifiers_only(physanim_ext, tmp_path):
    scene = _scene(tmp_path)
    ob = _default_emitter(scene)
    assert ob.physanim.emitter.output == 'USD_POINTS'

    assert bpy.ops.physanim.bake() == {'FINISHED'}

    res = ob.physanim.emitter.result
    assert res.type == 'POINTCLOUD'
    assert [(m.name, m.type) for m in res.modifiers] == NATIVE_MODIFIERS
    cache = res.modifiers["physanim_cache"]
    assert cache.object_path == "/particles"
    cache_file = cache.cache_file
    assert cache_file.is_sequence and cache_file.filepath.startswith("//")
    files = sorted(Path(bpy.path.abspath(cache_file.filepath)).parent.iterdir())
    assert [int(p.stem.rsplit("_", 1)[1]) for p in files] == list(range(1, 13))
    # Nothing of PhysAnim runs on a frame change of this object: no handler loads it.
    scene.frame_set(7)
    shown = result_points(res)
    cache = sys.modules[f"{physanim_ext.__name__}.core.cache"]
    cached = cache.read_frame(bpy.path.abspath(res.physanim.result.cache), 7)
    assert len(shown["id"]) == len(cached["id"]) > 50
    for name in ("id", "position", "velocity", "age", "size", "color"):
        assert shown[name].dtype == cached[name].dtype
        np.testing.assert_array_equal(shown[name], cached[name], err_msg=name)
    np.testing.assert_array_equal(shown["radius"], shown["size"])


_RENDER = textwrap.dedent('''
    import sys
    import bpy
    blend, frame, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    bpy.ops.wm.open_mainfile(filepath=blend)
    loaded = [m for m in sys.modules if "physanim" in m]
    enabled = [a.module for a in bpy.context.preferences.addons if "physanim" in a.module]
    assert not loaded and not enabled, (loaded, enabled)
    scene = bpy.context.scene
    scene.frame_set(frame)
    scene.render.filepath = out
    bpy.ops.render.render(write_still=True)
    print("rendered", out)
''')


def _camera_scene(scene) -> None:
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    camera.location = (0.0, -9.0, 1.5)
    camera.rotation_euler = (math.radians(85.0), 0.0, 0.0)
    scene.camera = camera
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", 'SUN'))
    sun.data.energy = 3.0
    sun.rotation_euler = (math.radians(60.0), 0.0, math.radians(-20.0))
    scene.collection.objects.link(sun)
    render = scene.render
    render.engine = 'CYCLES'
    scene.cycles.device, scene.cycles.samples, scene.cycles.use_denoising = 'CPU', 4, False
    render.resolution_x, render.resolution_y, render.resolution_percentage = 96, 64, 100
    render.film_transparent = True
    render.image_settings.file_format = 'PNG'
    render.image_settings.color_mode = 'RGBA'
    scene.view_settings.view_transform = 'Standard'


def _render_here(scene, path: Path, frame: int) -> np.ndarray:
    scene.frame_set(frame)
    return render_still(scene, path)


@pytest.mark.parametrize("render_as", ['OBJECT', 'BILLBOARD', 'GLOW', 'BLOBS', 'STREAKS'])
def test_renders_the_same_pixels_where_physanim_is_not_installed(physanim_ext, tmp_path,
                                                                  render_as):
    """Every Render As mode: the same pixels in a process where PhysAnim was never installed,
    and with the extension's own Points output."""
    scene = _scene(tmp_path, frame_end=10)
    ob = _default_emitter(scene)
    ob.hide_render = True
    p = ob.physanim.emitter
    p.render_as = render_as
    p.speed, p.spread, p.lifetime = 4.0, 0.6, 8.0
    stops = p.color_stops
    stops[0].color, stops[-1].color = (1.0, 0.1, 0.05, 1.0), (0.1, 0.3, 1.0, 1.0)
    _camera_scene(scene)
    blend = tmp_path / "shot.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    frame = 9
    with_extension = _render_here(scene, tmp_path / "with.png", frame)
    shown = with_extension[..., :3].sum(axis=2) > 0.05
    assert 0.01 < shown.mean() < 0.6, "the particles are not in the picture"
    rgb = with_extension[..., :3]
    red = (rgb[..., 0] > 2 * rgb[..., 2]) & shown
    blue = (rgb[..., 2] > 2 * rgb[..., 0]) & shown
    assert red.any() and blue.any(), "the colours over life did not reach the render"

    script = tmp_path / "render.py"
    script.write_text(_RENDER)
    env = {k: v for k, v in os.environ.items() if k != "BLENDER_USER_RESOURCES"}
    env["BLENDER_USER_SCRIPTS"] = str(tmp_path / "no_scripts")  # nothing user-installed either
    done = subprocess.run([sys.executable, str(script), str(blend), str(frame),
                           str(tmp_path / "without.png")], capture_output=True, text=True,
                          env=env, timeout=300)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    without = image_pixels(tmp_path / "without.png")
    np.testing.assert_array_equal(without, with_extension)

    # ... and the same pixels as the extension's own Points output of the same bake
    p.output = 'POINTS'
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert p.result.type == 'MESH'
    np.testing.assert_array_equal(_render_here(scene, tmp_path / "mesh.png", frame),
                                  with_extension)


def test_switching_the_output_replaces_the_result_and_leaves_nothing_behind(physanim_ext,
                                                                             tmp_path):
    scene = _scene(tmp_path, frame_end=6)
    ob = _default_emitter(scene)
    p = ob.physanim.emitter
    group = bpy.data.collections.new("FX")
    scene.collection.children.link(group)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    res = p.result
    name = res.name
    for coll in list(res.users_collection):
        coll.objects.unlink(res)
    group.objects.link(res)  # the user moved the result into a collection of their own

    for output, kind in (('POINTS', 'MESH'), ('OBJECTS', 'MESH'), ('USD_POINTS', 'POINTCLOUD'),
                         ('USD_POINTS', 'POINTCLOUD')):
        p.output = output
        assert bpy.ops.physanim.bake() == {'FINISHED'}
        res = p.result
        assert (res.type, res.name, list(res.users_collection)) == (kind, name, [group])
        scene.frame_set(5)
        assert len(result_points(res)["id"]) == 5 * 20  # the default rate: 20 a frame
        assert len(bpy.data.cache_files) == (1 if kind == 'POINTCLOUD' else 0)
        assert len(bpy.data.pointclouds) == (1 if kind == 'POINTCLOUD' else 0)
    assert bpy.ops.physanim.free_bake() == {'FINISHED'}
    assert p.result is None and name not in bpy.data.objects
    assert len(bpy.data.cache_files) == 0 and len(bpy.data.pointclouds) == 0
    assert not [g for g in bpy.data.node_groups if "physanim_usd_layout" in g]


def _baked_with_driven_frames(ext, ob):
    """Bake; the result and a reader of its cached frames. The cache file looks its files up
    by a driven frame: a simple expression, which Blender evaluates without Python."""
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    res = ob.physanim.emitter.result
    (driver,) = res.modifiers["physanim_cache"].cache_file.animation_data.drivers
    assert driver.driver.is_simple_expression
    cache = sys.modules[f"{ext.__name__}.core.cache"]
    folder = bpy.path.abspath(res.physanim.result.cache)
    return res, lambda frame: cache.read_frame(folder, frame)


def test_frames_below_one_play_from_their_own_files(physanim_ext, tmp_path):
    """Blender reads a file's number without its sign: files are numbered from the bake's first
    frame and the cache file's frame offset maps them back."""
    scene = _scene(tmp_path)
    scene.physanim.frame_start, scene.physanim.frame_end = -4, 6
    ob = _default_emitter(scene)
    ob.physanim.emitter.frame_start = -4
    res, read = _baked_with_driven_frames(physanim_ext, ob)
    for frame in (-4, -1, 0, 1, 3, 6, -5, 7):
        scene.frame_set(frame)
        cached = read(frame)
        shown = result_points(res)
        if cached is None:
            assert len(shown["position"]) == 0, frame
            continue
        assert len(cached["id"]) == 20 * (frame + 5)
        np.testing.assert_array_equal(shown["id"], cached["id"], err_msg=str(frame))
        np.testing.assert_array_equal(shown["position"], cached["position"], err_msg=str(frame))


_OPEN_AT = textwrap.dedent('''
    import sys
    import bpy
    bpy.ops.wm.open_mainfile(filepath=sys.argv[1])
    scene = bpy.context.scene
    for frame in map(int, sys.argv[2:]):
        scene.frame_set(frame)
        bpy.context.evaluated_depsgraph_get()
        print("shown frame", frame)
''')


def test_frames_outside_the_bake_show_no_points_and_no_modifier_error(physanim_ext, tmp_path):
    """A shot baked at frames 3-6 seen from frame 1, or opened at frame 9: no file has those
    numbers, and the cache modifier's reader, first made there, failed ("Could not create cache
    reader", the modifier in red) until the frame entered the bake."""
    scene = _scene(tmp_path, frame_end=6)
    scene.physanim.frame_start = 3
    ob = _default_emitter(scene)
    scene.frame_set(1)
    res, read = _baked_with_driven_frames(physanim_ext, ob)
    for frame in (1, 2, 3, 6, 7, 9, 4):
        scene.frame_set(frame)
        shown, cached = result_points(res), read(frame)
        if cached is None:
            assert len(shown["position"]) == 0, frame
        else:
            assert len(cached["id"]) > 0
            np.testing.assert_array_equal(shown["id"], cached["id"], err_msg=str(frame))

    # Blender logs the modifier's error: read it where a user opens the file, at each end
    for frame in (1, 9):
        scene.frame_set(frame)
        bpy.ops.wm.save_mainfile()
        script = tmp_path / "open_at.py"
        script.write_text(_OPEN_AT)
        done = subprocess.run([sys.executable, str(script), bpy.data.filepath, "2", "7"],
                              capture_output=True, text=True, timeout=300)
        log = done.stdout + done.stderr  # the bpy module logs to stdout
        assert done.returncode == 0 and "shown frame 7" in done.stdout, log[-2000:]
        assert "Could not create cache reader" not in log, (frame, log[-2000:])


def test_a_rebake_shows_at_once_without_a_frame_change(physanim_ext, tmp_path):
    """Blender keeps a reader open per cache file: the rebake must not show the old frame."""
    scene = _scene(tmp_path, frame_end=6)
    ob = _default_emitter(scene)
    scene.frame_set(4)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    before = result_points(ob.physanim.emitter.result)["position"]
    ob.physanim.emitter.seed += 1
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert scene.frame_current == 4
    after = result_points(ob.physanim.emitter.result)["position"]
    assert before.shape == after.shape and not np.array_equal(before, after)


def test_stretch_instance_transforms_are_rebuilt_as_vectors(physanim_ext, tmp_path):
    scene = _scene(tmp_path, frame_end=5)
    ob = _default_emitter(scene)
    ob.physanim.emitter.stretch = 0.5
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    scene.frame_set(5)
    shown = result_points(ob.physanim.emitter.result)
    cache = sys.modules[f"{physanim_ext.__name__}.core.cache"]
    cached = cache.read_frame(bpy.path.abspath(ob.physanim.emitter.result.physanim.result.cache), 5)
    for name in ("instance_scale", "instance_rotation", "velocity", "color", "id"):
        np.testing.assert_array_equal(shown[name], cached[name], err_msg=name)
    assert not any(k.startswith(("instance_scale_", "color_", "physanim_id")) for k in shown)


def test_ids_beyond_float_precision_fail_naming_emitter_and_frame(physanim_ext):
    particles_bake = _addon(physanim_ext, "particles_bake")
    errors = sys.modules[f"{physanim_ext.__name__}.core.errors"]
    ob = bpy.data.objects.new("Spray", None)
    ids = np.array([5, 2 ** 24 + 1], np.int64)
    with pytest.raises(errors.PhysanimError) as caught:
        particles_bake.ParticleBake._check_usd_ids(ob, ids, 812)
    message = str(caught.value)
    assert '"Spray"' in message and "frame 812" in message and "16,777,217" in message
    assert "Points (Extension)" in message
    particles_bake.ParticleBake._check_usd_ids(ob, ids[:1], 812)


def test_the_render_panel_says_where_each_output_plays(physanim_ext):
    panels = _addon(physanim_ext, "panels")
    ob = bpy.data.objects.new("Spray", None)
    ob.physanim.emitter.enabled = True
    context = type("Context", (), {"object": ob})()
    shown = {}
    for output in ('USD_POINTS', 'POINTS', 'OBJECTS'):
        ob.physanim.emitter.output = output
        labels: list[str] = []
        panels.PHYSANIM_PT_emitter_look.draw(type("Panel", (), {"layout": LabelRecorder(labels)})(),
                                             context)
        shown[output] = " ".join(labels)
    assert "without PhysAnim" in shown['USD_POINTS']
    assert "usdc" in shown['USD_POINTS'] or "usda" in shown['USD_POINTS']
    assert "Needs PhysAnim" in shown['POINTS']


def _layers(folder: Path, modules) -> dict[str, dict[str, np.ndarray]]:
    """Every attribute of every USD layer in ``folder``, read through ``pxr``."""
    layers = {}
    for path in sorted(folder.iterdir()):
        stage = modules[0].Stage.Open(str(path))
        prim = stage.GetPrimAtPath("/particles")
        layers[path.name] = {a.GetName(): np.array(a.Get()) for a in prim.GetAttributes()
                             if a.Get() is not None}
    return layers


def test_a_process_of_its_own_writes_the_same_usd_layers(physanim_ext, tmp_path, monkeypatch):
    """Large emitters' .usdc layers are saved by child processes (off the bake's lock), two
    here taking the frames in turn: the same layers as the writer thread saves, Blender
    showing the cache's points from them."""
    usd_process = _addon(physanim_ext, "usd_process")
    compat = _addon(physanim_ext, "compat")
    started = []
    start = usd_process.UsdProcess.__init__

    def spy(self, site, **kwargs):
        start(self, site, **kwargs)
        started.append(self)

    monkeypatch.setattr(usd_process.UsdProcess, "__init__", spy)
    saved = []
    save = usd_process.UsdProcess.save

    def spy_save(self, path, data):
        saved.append((self, data[1]))
        save(self, path, data)

    monkeypatch.setattr(usd_process.UsdProcess, "save", spy_save)
    monkeypatch.setattr(usd_process, "process_count", lambda emitters=1: 2)
    scene = _scene(tmp_path, frame_end=8)
    ob = _default_emitter(scene)  # 20 a frame: below MIN_POINTS, written on the thread
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    res = ob.physanim.emitter.result
    folder = Path(bpy.path.abspath(res.modifiers["physanim_cache"].cache_file.filepath)).parent
    modules = compat.usd_modules()
    monkeypatch.setattr(usd_process, "MIN_POINTS", 0)
    if modules is None:  # no pxr (the 4.2 module): text layers, on the thread
        assert bpy.ops.physanim.bake() == {'FINISHED'}
        assert started == [] and {p.suffix for p in folder.iterdir()} == {".usda"}
        return
    by_thread = _layers(folder, modules)
    assert started == [] and len(by_thread) == 8

    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert len(started) == 2 and all(p._proc.poll() == 0 for p in started)  # ended with it
    assert saved == [(started[(f - 1) % 2], f) for f in range(1, 9)]  # in turn
    by_process = _layers(folder, modules)
    assert by_process.keys() == by_thread.keys()
    for name, layer in by_thread.items():
        assert by_process[name].keys() == layer.keys() and "points" in layer
        for key, values in layer.items():
            np.testing.assert_array_equal(by_process[name][key], values, err_msg=key)
    cache = sys.modules[f"{physanim_ext.__name__}.core.cache"]
    scene.frame_set(6)
    shown = result_points(res)
    cached = cache.read_frame(bpy.path.abspath(res.physanim.result.cache), 6)
    assert len(shown["id"]) == 6 * 20
    for name in ("id", "position", "velocity", "color"):
        np.testing.assert_array_equal(shown[name], cached[name], err_msg=name)


def test_a_large_emitters_process_starts_with_the_bake(physanim_ext, tmp_path, monkeypatch):
    """An emitter whose estimated peak reaches MIN_POINTS has its processes (two here) started
    as the bake starts, without waiting (pxr imports while the first frames simulate), and
    confirmed at its first large frame; one whose estimate stays below starts none; ones
    started whose frames never grow that large are ended with the bake, its layers written on
    the thread."""
    usd_process = _addon(physanim_ext, "usd_process")
    budget = _addon(physanim_ext, "budget")
    cache = sys.modules[f"{physanim_ext.__name__}.core.cache"]
    events: list[tuple] = []
    processes: list = []
    start, ready, write = (usd_process.UsdProcess.__init__, usd_process.UsdProcess.wait_ready,
                           cache.CacheWriter.write_frame)

    def spy_start(self, site, wait=True):
        events.append(("start", wait))
        processes.append(self)
        start(self, site, wait=wait)

    def spy_ready(self):
        events.append(("ready",))
        ready(self)

    def spy_write(self, stream, frame, arrays):
        events.append(("frame", frame, len(arrays["id"])))
        return write(self, stream, frame, arrays)

    monkeypatch.setattr(usd_process.UsdProcess, "__init__", spy_start)
    monkeypatch.setattr(usd_process.UsdProcess, "wait_ready", spy_ready)
    monkeypatch.setattr(cache.CacheWriter, "write_frame", spy_write)
    process_count = usd_process.process_count
    monkeypatch.setattr(usd_process, "process_count", lambda emitters=1: 2)
    scene = _scene(tmp_path, frame_end=8)
    ob = _default_emitter(scene)  # 20 a frame over 8 frames: at most 160 alive
    monkeypatch.setattr(usd_process, "MIN_POINTS", 100)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    folder = Path(bpy.path.abspath(
        ob.physanim.emitter.result.modifiers["physanim_cache"].cache_file.filepath)).parent
    if _addon(physanim_ext, "compat").usd_modules() is None:  # no pxr (4.2): text layers
        assert events == [("frame", f, 20 * f) for f in range(1, 9)] and processes == []
        assert {p.suffix for p in folder.iterdir()} == {".usda"}
        return
    frames = [("frame", f, 20 * f) for f in range(1, 9)]
    # started before the first frame was written; confirmed at frame 5 (100 points), whose
    # layer it saves from the npz just queued
    assert events == [("start", False)] * 2 + frames[:5] + [("ready",)] * 2 + frames[5:], events
    assert all(p._proc.poll() == 0 for p in processes) and len(list(folder.iterdir())) == 8

    events.clear()
    monkeypatch.setattr(usd_process, "MIN_POINTS", 200)  # beyond the estimate: none starts
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert events == frames and len(processes) == 2

    events.clear()  # an estimate above, frames below: started, unused, ended with the bake
    monkeypatch.setattr(budget, "emitter_estimates",
                        lambda *args: {ob.name: (1e6, 0.0)})
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert events == [("start", False)] * 2 + frames and len(processes) == 4
    assert all(p._proc.poll() is not None for p in processes[2:])

    events.clear()  # a pipeline that wants none: the writer thread writes the layers
    monkeypatch.setenv("PHYSANIM_USD_PROCESSES", "0")
    monkeypatch.setattr(usd_process, "process_count", process_count)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert events == frames and len(processes) == 4 and len(list(folder.iterdir())) == 8
    assert sorted(p.name for p in folder.iterdir()) == [f"points_{f:06d}.usdc"
                                                        for f in range(1, 9)]


def test_the_usd_process_reads_cache_frames_as_np_load_does(physanim_ext, tmp_path):
    """The child maps a cache frame's stored members instead of reading and checking them:
    the same arrays (values, dtypes, shapes, memory order) as ``np.load``, for every kind the
    cache writes and a few it does not; compressed members go through ``np.load``; a
    truncated member is refused, naming the file."""
    usd_process = _addon(physanim_ext, "usd_process")
    cache = sys.modules[f"{physanim_ext.__name__}.core.cache"]
    rng = np.random.default_rng(3)
    arrays = {"id": np.arange(7, dtype=np.int32), "position": rng.random((7, 3), np.float32),
              "color": rng.random((7, 4)).astype(np.float32), "empty": np.zeros((0, 3)),
              "flag": rng.random(7) > 0.5, "wide": rng.random((2, 3, 4)),
              "fortran": np.asfortranarray(rng.random((5, 3))), "scalar": np.array(2.5)}
    writer = cache.CacheWriter(tmp_path / "bake", background=False)
    stored = writer.write_frame("points", 1, arrays)
    compressed = tmp_path / "compressed.npz"
    np.savez_compressed(compressed, **arrays)
    for path in (stored, compressed):
        got = usd_process.read_npz(str(path))
        with np.load(path, allow_pickle=False) as loaded:
            assert got.keys() == set(loaded.files)
            for key in loaded.files:
                expected = loaded[key]
                assert got[key].dtype == expected.dtype and got[key].shape == expected.shape
                assert got[key].flags.f_contiguous == expected.flags.f_contiguous, key
                np.testing.assert_array_equal(got[key], expected, err_msg=key)
    cut = tmp_path / "cut.npz"
    data = stored.read_bytes()
    member = data.index(b"PK\x03\x04", 1)  # the second member: the first one loses its tail
    cut.write_bytes(data[:member - 8] + data[member:])
    with pytest.raises(Exception, match="cut.npz"):
        usd_process.read_npz(str(cut))
    writer.abort()


def test_the_usd_process_runs_pxr_on_one_thread_and_keeps_freed_memory(physanim_ext,
                                                                       monkeypatch):
    """The child stays on one core (pxr's pool would spin on the simulation's) and reuses
    freed memory; a value the user set for either is kept."""
    usd_process = _addon(physanim_ext, "usd_process")
    for name in ("PXR_WORK_THREAD_LIMIT", "MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_"):
        monkeypatch.delenv(name, raising=False)
    env = usd_process.child_environment()
    assert env["PXR_WORK_THREAD_LIMIT"] == "1"
    assert int(env["MALLOC_MMAP_THRESHOLD_"]) == 32 * 1024 * 1024
    assert int(env["MALLOC_TRIM_THRESHOLD_"]) >= 1 << 30
    monkeypatch.setenv("PXR_WORK_THREAD_LIMIT", "4")
    assert usd_process.child_environment()["PXR_WORK_THREAD_LIMIT"] == "4"


def test_the_usd_processes_are_the_cores_up_to_four_shared_by_the_emitters(physanim_ext,
                                                                           monkeypatch):
    usd_process = _addon(physanim_ext, "usd_process")
    monkeypatch.delenv("PHYSANIM_USD_PROCESSES", raising=False)
    for cores, emitters, count in ((1, 1, 1), (2, 1, 2), (16, 1, 4), (4, 2, 2), (16, 3, 1),
                                   (2, 5, 1)):
        monkeypatch.setattr(usd_process.os, "sched_getaffinity",
                            lambda pid, cores=cores: set(range(cores)))
        assert usd_process.process_count(emitters) == count, (cores, emitters)
    # a pipeline's own choice, whatever the cores (0: none, the writer thread writes them)
    for value, emitters, count in (("1", 1, 1), ("6", 1, 6), (" 6 ", 2, 3), ("2", 3, 1),
                                   ("0", 1, 0), ("0", 3, 0), ("32", 1, 32)):
        monkeypatch.setenv("PHYSANIM_USD_PROCESSES", value)
        assert usd_process.process_count(emitters) == count, (value, emitters)
    for value in ("-2", "two", "1.5", "1_000", "33", "²"):
        monkeypatch.setenv("PHYSANIM_USD_PROCESSES", value)
        with pytest.raises(ValueError, match=f"PHYSANIM_USD_PROCESSES .*{value!r}"):
            usd_process.process_count(1)


def test_a_bad_usd_process_count_fails_the_bake_naming_it(physanim_ext, tmp_path, monkeypatch):
    """A pipeline's PHYSANIM_USD_PROCESSES that is no count stops a bake that would start USD
    processes before anything is written, naming the variable and its value; the previous
    bake stays."""
    scene = _scene(tmp_path, frame_end=4)
    ob = _default_emitter(scene)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    cache = Path(bpy.path.abspath(ob.physanim.emitter.result.physanim.result.cache))
    before = sorted((p.name, p.read_bytes()) for p in cache.iterdir())
    folders = sorted(p.name for p in cache.parent.iterdir())
    monkeypatch.setenv("PHYSANIM_USD_PROCESSES", "lots")
    ob.physanim.emitter.rate = 30.0
    if _addon(physanim_ext, "compat").usd_modules() is None:  # no pxr (4.2): no process to
        assert bpy.ops.physanim.bake() == {'FINISHED'}  # count, the variable is not read
        return
    with pytest.raises(RuntimeError, match="PHYSANIM_USD_PROCESSES .*'lots'"):
        bpy.ops.physanim.bake()
    assert sorted((p.name, p.read_bytes()) for p in cache.iterdir()) == before
    assert sorted(p.name for p in cache.parent.iterdir()) == folders  # no partial folder


def test_a_bake_failing_as_it_starts_its_usd_processes_leaves_none(physanim_ext, tmp_path,
                                                                    monkeypatch):
    """Two large emitters: the first one's processes start, the second's fail to; the bake
    stops with that error and ends the first one's processes, leaving no partial folder."""
    usd_process = _addon(physanim_ext, "usd_process")
    particles_bake = _addon(physanim_ext, "particles_bake")
    scene = _scene(tmp_path, frame_end=4)
    for x in (-2.0, 2.0):
        _default_emitter(scene).location.x = x
    monkeypatch.setattr(usd_process, "MIN_POINTS", 10)
    monkeypatch.setattr(usd_process, "process_count", lambda emitters=1: 2)
    pools = []
    spawn = particles_bake.ParticleBake._spawn

    def failing_spawn(self, wait):
        if pools:
            raise RuntimeError("no second pool")
        pools.append(spawn(self, wait))
        return pools[-1]

    monkeypatch.setattr(particles_bake.ParticleBake, "_spawn", failing_spawn)
    root = Path(bpy.path.abspath("//"))
    if _addon(physanim_ext, "compat").usd_modules() is None:  # no pxr (4.2): none to start
        assert bpy.ops.physanim.bake() == {'FINISHED'} and pools == []
        return
    with pytest.raises(RuntimeError, match="no second pool"):
        bpy.ops.physanim.bake()
    assert [p.name for p in root.rglob("*") if p.is_file()] == ["shot.blend"]
    assert not [p for p in root.rglob("*") if ".partial-" in p.name]
    assert len(pools) == 1 and len(pools[0].processes) == 2
    assert all(p._proc.poll() is not None for p in pools[0].processes)


def test_the_usd_process_names_a_layer_it_cannot_write(physanim_ext, tmp_path):
    usd_process = _addon(physanim_ext, "usd_process")
    site = _addon(physanim_ext, "compat").usd_site()
    with pytest.raises(OSError, match="cannot import pxr from /nowhere"):
        usd_process.UsdProcess("/nowhere")
    pool = usd_process.UsdPool("/nowhere", 2, wait=False)  # both start; neither can import
    with pytest.raises(OSError, match="cannot import pxr from /nowhere"):
        pool.wait_ready()
    assert len(pool.processes) == 2 and all(p._proc.poll() is not None for p in pool.processes)
    if site is None:
        return
    cache = sys.modules[f"{physanim_ext.__name__}.core.cache"]
    writer = cache.CacheWriter(tmp_path / "bake")
    process = usd_process.UsdProcess(site)
    writer.attach(process)
    arrays = {"position": np.zeros((3, 3), np.float32), "id": np.arange(3)}
    good = writer.write_frame("points", 1, arrays)
    writer.write_file("usd", "points_000001.usdc", process.save, (good, 1))
    writer.flush()
    assert (writer.partial_dir / "usd" / "points_000001.usdc").is_file()
    missing = tmp_path / "gone.npz"
    writer.write_file("usd", "points_000002.usdc", process.save, (missing, 2))
    with pytest.raises(OSError, match=r'points_000002\.usdc" \(frame 2\) was not written.*gone'):
        writer.commit({})
    assert process._proc.poll() is not None  # ended with the failed commit
    writer.abort()
    assert not (tmp_path / "bake").exists() and not writer.partial_dir.exists()
    # a cancelled bake kills its process
    writer = cache.CacheWriter(tmp_path / "bake")
    process = usd_process.UsdProcess(site)
    writer.attach(process)
    writer.abort()
    assert process._proc.poll() is not None and not writer.partial_dir.exists()


_HUNG_PXR = '''
import time
class _Stage:
    @staticmethod
    def CreateNew(path):
        time.sleep(3600)  # a pxr that never finishes saving
class Usd:
    Stage = _Stage
Sdf = UsdGeom = Vt = None
'''


def test_a_usd_process_that_hangs_fails_the_bake_instead_of_holding_it(physanim_ext, tmp_path,
                                                                        monkeypatch):
    """A child whose pxr never finishes a layer (a hung library, a dead network disk) is
    killed once it has saved nothing for STALL_TIMEOUT seconds, and the wait for its queue —
    at the bake's end, or when it is closed without one — fails naming it: a farm job ends
    instead of waiting for ever, and the bake's files are thrown away as on any failure."""
    usd_process = _addon(physanim_ext, "usd_process")
    cache = sys.modules[f"{physanim_ext.__name__}.core.cache"]
    site = tmp_path / "site"
    (site / "pxr").mkdir(parents=True)
    (site / "pxr" / "__init__.py").write_text(_HUNG_PXR)
    monkeypatch.setattr(usd_process, "STALL_TIMEOUT", 1.5)
    arrays = {"position": np.zeros((3, 3), np.float32), "id": np.arange(3)}
    for ending in ("commit", "close"):
        writer = cache.CacheWriter(tmp_path / "bake")
        process = usd_process.UsdProcess(str(site))
        writer.attach(process)
        frame = writer.write_frame("points", 1, arrays)
        writer.write_file("usd", "points_000001.usdc", process.save, (frame, 1))
        start = time.monotonic()
        with pytest.raises(OSError, match=r"saved no layer in 1\.5 s \(1 waiting\) and was stopped"):
            if ending == "commit":
                writer.commit({})
            else:
                while writer._pending:  # the layer handed to the child, not synced
                    writer._pending.pop(0).result()
                process.close()
        assert time.monotonic() - start < 10.0
        assert process._proc.poll() is not None  # killed
        writer.abort()
        assert not (tmp_path / "bake").exists() and not writer.partial_dir.exists()
