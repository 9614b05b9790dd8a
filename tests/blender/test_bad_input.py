"""Bad input and interrupted bakes: every failure names the object, the frame and the value, and
leaves the previous bake exactly as it was (cache files, result objects, bake hash).

Each test bakes a small scene successfully first, records it, then makes the next bake fail.
"""
from __future__ import annotations

import math
import random
import sys
from pathlib import Path

import bmesh
import bpy
import numpy as np
import pytest

from sample_scenes._common import result_points

FRAME_START, FRAME_END = 2, 9
SHOWN_FRAMES = (3, 7)


# ------------------------------------------------------------------------------------- helpers

def _emitter(name: str, data=None, **props) -> bpy.types.Object:
    ob = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(ob)
    p = ob.physanim.emitter
    p.enabled = True
    values = dict(rate=5.0, lifetime=4.0, lifetime_random=1.0, speed=2.0)
    values.update(props)
    for key, value in values.items():
        setattr(p, key, value)
    return ob


def _mesh(name: str, make) -> bpy.types.Mesh:
    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    try:
        make(bm)
        bm.to_mesh(me)
    finally:
        bm.free()
    return me


def _grid(bm):
    bmesh.ops.create_grid(bm, x_segments=2, y_segments=2, size=1.0)


def _cube(bm):
    bmesh.ops.create_cube(bm, size=1.0)


def _open_cube(bm):
    bmesh.ops.create_cube(bm, size=1.0)
    bm.faces.ensure_lookup_table()
    bmesh.ops.delete(bm, geom=[bm.faces[0]], context='FACES_ONLY')


def _wire(bm):
    """Four vertices joined by three edges: no faces."""
    verts = [bm.verts.new((float(i), 0.0, 0.0)) for i in range(4)]
    for a, b in zip(verts, verts[1:]):
        bm.edges.new((a, b))


def _scene():
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = FRAME_START, FRAME_END
    scene.physanim.frame_start, scene.physanim.frame_end = FRAME_START, FRAME_END
    scene.frame_set(FRAME_START)
    return scene


def _save(tmp_path: Path) -> None:
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "scene.blend"))


def _cache_root(scene) -> Path:
    return Path(bpy.path.abspath(scene.physanim.cache_dir))


def _files(root: Path) -> dict[str, tuple[bytes, int]]:
    return {str(p.relative_to(root)): (p.read_bytes(), p.stat().st_mtime_ns)
            for p in sorted(root.rglob("*")) if p.is_file()}


def _leftovers(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if ".partial-" in p.name or ".old-" in p.name]


def _shown(res) -> dict[str, np.ndarray]:
    return result_points(res)


class Baked:
    """Everything a failed or cancelled bake must leave as it was."""

    def __init__(self, scene, root: Path):
        self.scene, self.root = scene, root
        self.files = _files(root)
        assert self.files, "the first bake wrote nothing"
        self.hash, self.info = scene.physanim.bake_hash, scene.physanim.bake_info
        self.results = self._results()
        self.objects = {o.name for o in bpy.data.objects}

    def _results(self) -> dict:
        out = {}
        frame = self.scene.frame_current
        for ob in self.scene.objects:
            res = ob.physanim.emitter.result
            if not ob.physanim.emitter.enabled or res is None:
                continue
            shown = []
            for f in SHOWN_FRAMES:
                self.scene.frame_set(f)
                shown.append(_shown(res))
            out[ob.name] = (res.name, res.physanim.result.cache, len(res.modifiers), shown)
        self.scene.frame_set(frame)
        return out

    def assert_intact(self) -> None:
        assert _files(self.root) == self.files, "the previous cache changed"
        assert not _leftovers(self.root), "partial folders were left behind"
        assert (self.scene.physanim.bake_hash, self.scene.physanim.bake_info) == (self.hash,
                                                                                  self.info)
        assert {o.name for o in bpy.data.objects} == self.objects
        now = self._results()
        assert now.keys() == self.results.keys()
        for name, (res, cache, modifiers, shown) in self.results.items():
            assert now[name][:3] == (res, cache, modifiers), name
            assert len(shown[0]["position"]) > 0
            for before, after in zip(shown, now[name][3]):
                assert before.keys() == after.keys()
                assert all(np.array_equal(before[k], after[k]) for k in before), name


def _bake_first() -> Baked:
    scene = bpy.context.scene
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    return Baked(scene, _cache_root(scene))


def _bake_fails(*parts: str) -> str:
    """Bake, expecting an error report whose message contains every one of ``parts``."""
    with pytest.raises(RuntimeError) as info:
        bpy.ops.physanim.bake()
    message = str(info.value)
    for part in parts:
        assert part in message, f"{part!r} not in the message: {message}"
    return message


def _keys(ob, data_path: str, index: int, keys, interpolation='LINEAR') -> None:
    """Key ``ob.<data_path>[index]`` at (frame, value) pairs (values may be NaN or inf)."""
    for frame, _value in keys:
        ob.keyframe_insert(data_path, index=index, frame=frame)
    curve = _fcurve(ob, data_path, index)
    for point, (frame, value) in zip(curve.keyframe_points, keys):
        point.co = (frame, value)
        point.interpolation = interpolation
    curve.update()


def _fcurve(ob, data_path: str, index: int):
    ad = ob.animation_data
    if hasattr(bpy.types, "ActionSlot"):  # 4.4+: curves live in the slot's channelbag
        for layer in ad.action.layers:
            for strip in layer.strips:
                bag = strip.channelbag(ad.action_slot)
                found = bag and bag.fcurves.find(data_path, index=max(index, 0))
                if found:
                    return found
        raise AssertionError(f"no F-curve {data_path}[{index}]")
    return ad.action.fcurves.find(data_path, index=max(index, 0))


# ------------------------------------------------------------------------- emitter sources

def test_faces_source_on_a_mesh_without_faces(physanim_ext, tmp_path):
    _scene()
    ob = _emitter("Wire", _mesh("Sheet", _grid))
    ob.physanim.emitter.source = 'FACES'
    _save(tmp_path)
    baked = _bake_first()

    ob.data = _mesh("Wire", _wire)
    _bake_fails('emitter "Wire"', f"frame {FRAME_START}", "FACES", "0 faces")
    baked.assert_intact()


def test_volume_source_on_an_open_mesh(physanim_ext, tmp_path):
    _scene()
    ob = _emitter("Box", _mesh("Closed", _cube))
    ob.physanim.emitter.source = 'VOLUME'
    _save(tmp_path)
    baked = _bake_first()

    ob.data = _mesh("Open", _open_cube)  # one face deleted: 4 open edges
    _bake_fails('emitter "Box"', f"frame {FRAME_START}", "VOLUME", "not closed", "4 open")
    baked.assert_intact()


# ------------------------------------------------------------------- non-finite values

@pytest.mark.parametrize("drag", ["quadratic", "linear"])
def test_diverging_simulation_fails_naming_emitter_frame_and_value(physanim_ext, tmp_path, drag):
    """An enormous drag on light particles (explicit Euler) from frame 5 on overflows: the bake
    must stop with a message, never write inf/NaN (or clamp) into the cache."""
    scene = _scene()
    scene.physanim.integrator = 'EULER'
    _emitter("Spray", mass=1e-6)
    air = bpy.data.objects.new("Air", None)
    scene.collection.objects.link(air)
    air.physanim.force.enabled = True
    air.physanim.force.type = 'DRAG'
    air.physanim.force.linear = 0.0
    _save(tmp_path)
    baked = _bake_first()

    _keys(air, f"physanim.force.{drag}", -1, [(1, 0.0), (5, 1.0e6)], interpolation='CONSTANT')
    message = _bake_fails('emitter "Spray"')
    frames = [f for f in range(5, FRAME_END + 1) if f"frame {f}:" in message]
    assert frames, f"no frame from 5 on named: {message}"
    assert "inf" in message or "nan" in message or "e+" in message, message  # the value
    baked.assert_intact()


def test_emitter_location_becoming_nan_names_the_frame(physanim_ext, tmp_path):
    scene = _scene()
    ob = _emitter("Jumper")
    _save(tmp_path)
    baked = _bake_first()

    # 0 up to frame 6 (constant), NaN from frame 6 on
    _keys(ob, "location", 0, [(1, 0.0), (6, math.nan)], interpolation='CONSTANT')
    scene.frame_set(6)
    assert math.isnan(ob.location.x)
    scene.frame_set(FRAME_START)
    _bake_fails('"Jumper"', "frame 6", "nan")
    baked.assert_intact()


@pytest.mark.parametrize("kind, data_path", [("emitter", "physanim.emitter.rate"),
                                             ("emitter", "physanim.emitter.speed"),
                                             ("force", "physanim.force.strength"),
                                             ("collider", "physanim.collider.friction")])
def test_keyed_nan_property_names_object_frame_and_value(physanim_ext, tmp_path, kind, data_path):
    _scene()
    ob = _emitter("Keyed")
    ob.physanim.force.enabled = ob.physanim.collider.enabled = True
    ob.physanim.collider.shape = 'SPHERE'
    _save(tmp_path)
    baked = _bake_first()

    _keys(ob, data_path, -1, [(1, 1.0), (6, math.nan)], interpolation='CONSTANT')
    _bake_fails(f'{kind} "Keyed" at frame 6', data_path.rpartition(".")[2], "nan")
    baked.assert_intact()


def test_emitter_thrown_beyond_float_range_is_an_error(physanim_ext, tmp_path):
    """Blender clamps an infinite location key to the float maximum (3.4e38 m); a particle
    born during the jump (frame 5 -> 6) is beyond the world bound and inherits a speed beyond
    the speed limit: the bake fails naming the emitter and the frame the interval starts at."""
    _scene()
    ob = _emitter("Jumper", inherit_velocity=1.0)
    _save(tmp_path)
    baked = _bake_first()

    _keys(ob, "location", 0, [(1, 0.0), (5, 0.0), (6, math.inf)])
    _bake_fails('"Jumper"', "frame 5", "beyond the world bound")
    baked.assert_intact()


# -------------------------------------------------------------------------- cache folder

def test_cache_folder_below_a_file_is_not_writable(physanim_ext, tmp_path):
    scene = _scene()
    _emitter("Fountain")
    _save(tmp_path)
    baked = _bake_first()

    blocker = tmp_path / "blocker"
    blocker.write_text("a file, not a folder")
    scene.physanim.cache_dir = str(blocker / "cache")
    _bake_fails(str(blocker))
    assert blocker.read_text() == "a file, not a folder"
    baked.assert_intact()
    assert not _leftovers(tmp_path)


def test_relative_cache_path_in_an_unsaved_file(physanim_ext, tmp_path):
    scene = _scene()
    _emitter("Fountain")
    scene.physanim.cache_dir = str(tmp_path / "absolute_cache")
    assert not bpy.data.filepath
    baked = _bake_first()

    scene.physanim.cache_dir = "//physanim_cache"
    message = _bake_fails("//physanim_cache", "save")
    assert scene.name in message
    baked.assert_intact()
    assert not (tmp_path / "physanim_cache").exists()


def test_nothing_to_bake_and_reversed_frame_range(physanim_ext, tmp_path):
    scene = _scene()
    ob = _emitter("Fountain")
    _save(tmp_path)
    baked = _bake_first()

    scene.physanim.frame_start, scene.physanim.frame_end = 9, 4
    _bake_fails("frame end 4", "frame start 9")
    baked.assert_intact()
    scene.physanim.frame_start, scene.physanim.frame_end = FRAME_START, FRAME_END
    ob.physanim.emitter.enabled = False
    _bake_fails("nothing to bake")
    ob.physanim.emitter.enabled = True
    baked.assert_intact()


# ------------------------------------------------------------------------------- cancel

def test_cancel_at_random_frames_keeps_the_previous_bake(physanim_ext, tmp_path):
    bake = sys.modules[f"{physanim_ext.__name__}.addon.bake"]
    scene = _scene()
    a = _emitter("A", seed=1)
    _emitter("B", seed=2, rate=3.0)
    _save(tmp_path)
    baked = _bake_first()
    a.physanim.emitter.rate = 8.0  # a finished re-bake would change A's cache

    rng = random.Random(20240607)
    for k in sorted({0, FRAME_END - FRAME_START - 1, *rng.sample(range(FRAME_END - FRAME_START),
                                                                 3)}):
        scene.frame_set(SHOWN_FRAMES[1])
        job = bake.BakeJob(bpy.context)
        for _ in range(k):
            assert job.step(bpy.context) is False
        assert job.frame == FRAME_START + k
        assert _leftovers(baked.root), "the job writes into a partial folder"
        job.abort()
        assert scene.frame_current == SHOWN_FRAMES[1], f"cancel at step {k} moved the frame"
        baked.assert_intact()
    assert not _leftovers(tmp_path)


def test_collider_keyed_to_zero_scale_names_object_and_frame(tmp_path):
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "flat.blend"))
    scene = bpy.context.scene
    scene.physanim.frame_start, scene.physanim.frame_end = 1, 8
    emitter = bpy.data.objects.new("Spray", None)
    scene.collection.objects.link(emitter)
    emitter.physanim.emitter.enabled = True
    ground = bpy.data.objects.new("Squashed", None)
    scene.collection.objects.link(ground)
    ground.physanim.collider.enabled = True
    for frame, z in ((1, 1.0), (5, 1.0), (6, 0.0)):
        ground.scale = (1.0, 1.0, z)
        ground.keyframe_insert("scale", index=2, frame=frame)
    with pytest.raises(RuntimeError, match=r'collider "Squashed" at frame 6: .*zero scale.*'
                                           r'scale \(1\.0, 1\.0, 0\.0\)'):
        bpy.ops.physanim.bake()


def test_lifetime_random_beyond_lifetime_is_named_in_frames(tmp_path):
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "life.blend"))
    scene = bpy.context.scene
    scene.physanim.frame_start, scene.physanim.frame_end = 1, 5
    ob = bpy.data.objects.new("Short", None)
    scene.collection.objects.link(ob)
    p = ob.physanim.emitter
    p.enabled = True
    p.lifetime, p.lifetime_random = 10.0, 12.0
    with pytest.raises(RuntimeError, match=r'emitter "Short" at frame 1: lifetime_random 12 frames '
                                           r'is larger than lifetime 10 frames'):
        bpy.ops.physanim.bake()


# ------------------------------------------------------------- limits on what Blender owns

@pytest.mark.parametrize("change, parts", [
    (lambda sc, ob: setattr(sc, "gravity", (0.0, 0.0, -1e35)),
     ('scene "Scene"', "gravity", "-1e+35", "limit")),
    (lambda sc, ob: setattr(sc.render, "fps_base", 1e-5),
     ('scene "Scene"', "frame rate", "2.4e+06 fps")),
    (lambda sc, ob: setattr(ob, "scale", (1e9, 1.0, 1.0)),
     ('"Fountain"', f"frame {FRAME_START}", "scale", "1e+09")),
    (lambda sc, ob: setattr(sc.physanim, "frame_end", FRAME_START + 200_000),
     ('scene "Scene"', "200,001 frames", "100,000")),
])
def test_absurd_blender_values_fail_before_baking(physanim_ext, tmp_path, change, parts):
    scene = _scene()
    ob = _emitter("Fountain")
    _save(tmp_path)
    baked = _bake_first()
    change(scene, ob)
    _bake_fails(*parts)
    baked.assert_intact()


def test_particles_beyond_the_world_bound_or_speed_limit_fail(physanim_ext, tmp_path):
    scene = _scene()
    ob = _emitter("Fountain", speed=3.0)
    _save(tmp_path)
    baked = _bake_first()
    scene.physanim.speed_limit = 2.0  # the launch speed is 3 m/s
    _bake_fails('emitter "Fountain"', "speed 2.8", "beyond the speed limit (2 m/s)")
    baked.assert_intact()
    scene.physanim.speed_limit = 1e5
    scene.physanim.world_bound = 1.0
    ob.location = (0.0, 0.0, 0.99)  # launched upwards at 3 m/s
    _bake_fails('emitter "Fountain"', "beyond the world bound (±1 m)")
    baked.assert_intact()


def test_spring_mesh_beyond_the_speed_limit_fails(physanim_ext, tmp_path):
    scene = _scene()
    _emitter("Fountain", speed=0.2, lifetime=1.0, lifetime_random=0.0)  # never reaches 1 m/s
    cloth = bpy.data.objects.new("Cloth", _mesh("Cloth", _grid))
    scene.collection.objects.link(cloth)
    cloth.physanim.spring_mesh.enabled = True
    _save(tmp_path)
    baked = _bake_first()
    mesh_files = {k: v for k, v in baked.files.items() if k.split("/")[1] == "spring_meshes"}
    particle_files = {k: v for k, v in baked.files.items() if k not in mesh_files}
    assert mesh_files and particle_files
    modifier = cloth.modifiers["physanim"].filepath
    scene.physanim.speed_limit = 1.0  # it falls faster than 1 m/s after about 4 frames
    # the spring mesh fails and keeps its previous bake; the emitter is fine and bakes anyway
    _bake_fails('spring mesh "Cloth" at frame', "beyond the speed limit (1 m/s)",
                'not baked (previous bake kept): spring mesh "Cloth"', "the rest baked (1 emitter")
    now = _files(baked.root)
    assert {k: v for k, v in now.items() if k in mesh_files} == mesh_files
    assert cloth.modifiers["physanim"].filepath == modifier
    rebaked = {k: v for k, v in now.items() if k.split("/")[1] != "spring_meshes"}
    assert rebaked.keys() == particle_files.keys()
    assert all(rebaked[k][1] != particle_files[k][1] for k in rebaked)  # written again
    assert not _leftovers(baked.root)


def test_a_failing_emitter_does_not_stop_a_spring_mesh(physanim_ext, tmp_path):
    scene = _scene()
    orphan = _emitter("Orphan")
    orphan.physanim.emitter.source = 'DEATHS'  # no parent emitter: the particles cannot bake
    cloth = bpy.data.objects.new("Cloth", _mesh("Cloth", _grid))
    scene.collection.objects.link(cloth)
    cloth.physanim.spring_mesh.enabled = True
    _save(tmp_path)
    message = _bake_fails('emitter "Orphan"', "parent", 'not baked (previous bake kept): '
                          'particles (emitter "Orphan")', "the rest baked (0 emitter(s), 1 spring")
    assert cloth.modifiers["physanim"].type == 'MESH_CACHE'  # the cloth baked all the same
    assert orphan.physanim.emitter.result is None
    assert message.count("Orphan") == 2
    assert not _leftovers(_cache_root(scene))


@pytest.mark.parametrize("when", ["first frame", "mid-bake"])
def test_an_emitter_that_cannot_be_read_does_not_stop_a_spring_mesh(physanim_ext, tmp_path, when):
    """Reading an emitter's values is the particle system's business: an emitter that cannot be
    read — an empty with a mesh source from the first frame, or a mesh whose vertex count a
    Build modifier changes during the bake — fails the particles and the cloth still bakes
    (the fuzzer found the first one ending in a Python traceback)."""
    scene = _scene()
    if when == "first frame":
        bad = _emitter("Bad")
        bad.physanim.emitter.source = 'VERTS'
        parts = ('emitter "Bad"', "needs a mesh object (this is an Empty)")
    else:
        bad = bpy.data.objects.new("Bad", _mesh("Bad", _grid))
        scene.collection.objects.link(bad)
        bad.physanim.emitter.enabled = True
        bad.physanim.emitter.source = 'VERTS'
        build = bad.modifiers.new("Build", 'BUILD')
        build.frame_start, build.frame_duration = FRAME_START - 3, 2 * (FRAME_END - FRAME_START)
        parts = ('emitter "Bad"', "vertex count")
    cloth = bpy.data.objects.new("Cloth", _mesh("Cloth", _grid))
    scene.collection.objects.link(cloth)
    cloth.physanim.spring_mesh.enabled = True
    _save(tmp_path)
    message = _bake_fails(*parts, 'not baked (previous bake kept): particles (emitter "Bad")',
                          "the rest baked (0 emitter(s), 1 spring")
    assert "Traceback" not in message
    assert cloth.modifiers["physanim"].type == 'MESH_CACHE'  # the cloth baked all the same
    assert bad.physanim.emitter.result is None
    assert not _leftovers(_cache_root(scene))


@pytest.mark.parametrize("what, column, value, says", [
    ("position", "particle_x", math.nan, "position became [nan"),
    ("velocity", "particle_v", -math.inf, "velocity became [-inf"),
    ("position", "particle_x", -1e39, "position reached [-1.e+39"),
    ("velocity", "particle_v", 5e38, "velocity reached [5.e+38"),
    ("size", "particle_size", math.inf, "size became [inf"),
    ("age", "particle_age", 1e300, "age reached [1.e+300"),
])
def test_values_the_float32_cache_cannot_hold_name_particle_emitter_and_frame(
        physanim_ext, what, column, value, says):
    P = sys.modules[f"{physanim_ext.__name__}.core.particles"]
    particles_bake = sys.modules[f"{physanim_ext.__name__}.addon.particles_bake"]
    builder = P.ParticleModelBuilder(seed=0)
    builder.add_emitter(P.EmitterSettings(name="Spray"))
    model = builder.finalize(0)
    state = model.state(0.0)
    big = 3.0e38  # within float32 (3.4e38): fine
    state.append(0, np.full((3, 3), big), np.full((3, 3), -big), np.ones(3), np.full(3, big),
                 np.full(3, 1e6), np.full(3, big))
    bake = particles_bake.ParticleBake.__new__(particles_bake.ParticleBake)
    bake.model = model
    bake._check_cache_range(state, 9)
    getattr(state, column)[1] = value
    with pytest.raises(Exception) as caught:
        bake._check_cache_range(state, 9)
    message = str(caught.value)
    ident = int(state.particle_id[1])
    assert f"particle {ident} {says}" in message, message
    assert '"Spray"' in message and "frame 9" in message, message
