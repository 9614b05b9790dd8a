"""Render As (addon/render_modes.py): objects, billboards, glowing points, blobs and streaks, each
set at its defaults on a default emitter and checked in the evaluated scene and in a render."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest
from mathutils import Vector

from physanim.tests.blender.probes import render_still
from sample_scenes._common import result_points

FRAME = 10


def _scene(tmp_path: Path):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    scene.physanim.frame_start, scene.physanim.frame_end = 1, 12
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    camera.location = (1.0, -8.0, 1.0)
    camera.rotation_euler = (math.radians(90.0), 0.0, math.radians(7.0))
    scene.camera = camera
    render = scene.render
    render.engine = 'CYCLES'
    scene.cycles.device, scene.cycles.samples, scene.cycles.use_denoising = 'CPU', 8, False
    render.resolution_x, render.resolution_y, render.resolution_percentage = 96, 72, 100
    render.film_transparent = True
    render.image_settings.file_format = 'OPEN_EXR'
    scene.view_settings.view_transform = 'Standard'
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "modes.blend"))
    return scene


def _baked(scene, mode: str, **props):
    """A default emitter (a plane, its switch on) with only Render As (and ``props``) set."""
    bpy.ops.mesh.primitive_plane_add(size=1.0)
    ob = bpy.context.object
    p = ob.physanim.emitter
    ob.hide_render = True  # the emitter plane itself would catch the glows' light
    p.enabled = True
    p.render_as = mode
    for key, value in props.items():
        setattr(p, key, value)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    scene.frame_set(FRAME)
    return ob


def _render(scene, path: Path) -> np.ndarray:
    return render_still(scene, path)


def _faces_camera(m, camera) -> bool:
    """Whether an instance's local +Z (its face) points at the camera."""
    normal = (m.to_3x3() @ Vector((0.0, 0.0, 1.0))).normalized()
    return normal.dot((camera - m.translation).normalized()) > 0.9999


def _instances(res) -> list:
    """World matrices of the instances the result makes."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    return [inst.matrix_world.copy() for inst in depsgraph.object_instances
            if inst.is_instance and inst.parent is not None and inst.parent.original == res]


def _matched(points: dict, matrices: list) -> list[tuple[int, object]]:
    """(point index, instance matrix) pairs, matched by position."""
    position = points["position"]
    pairs = []
    for m in matrices:
        i = int(np.argmin(np.linalg.norm(position - np.array(m.translation), axis=1)))
        assert np.linalg.norm(position[i] - np.array(m.translation)) < 1e-5
        pairs.append((i, m))
    return pairs


def test_objects_by_default(physanim_ext, tmp_path):
    scene = _scene(tmp_path)
    ob = _baked(scene, 'OBJECT')
    res = ob.physanim.emitter.result
    points = result_points(res)
    pairs = _matched(points, _instances(res))
    assert len(pairs) == len(points["position"]) > 50
    for i, m in pairs:
        np.testing.assert_allclose(m.to_scale(), [points["size"][i]] * 3, rtol=1e-5)
    image = _render(scene, tmp_path / "objects.exr")
    assert (image[..., 3] > 0.5).mean() > 0.01


def test_billboards_face_the_camera(physanim_ext, tmp_path):
    scene = _scene(tmp_path)
    ob = _baked(scene, 'BILLBOARD')
    res = ob.physanim.emitter.result
    points = result_points(res)
    pairs = _matched(points, _instances(res))
    assert len(pairs) == len(points["position"]) > 50
    camera = scene.camera.matrix_world.translation
    for i, m in pairs:
        assert _faces_camera(m, camera)
        np.testing.assert_allclose(m.to_scale(), [points["size"][i]] * 3, rtol=1e-5)
    # the camera moves: they turn with it (the node tree looks up the active camera)
    scene.camera.location.x += 3.0
    camera = scene.camera.matrix_world.translation
    assert all(_faces_camera(m, camera) for _i, m in _matched(points, _instances(res)))
    scene.camera.location.x -= 3.0
    image = _render(scene, tmp_path / "billboards.exr")
    alpha = image[..., 3]
    # soft dots: coverage fades out from each centre, so many pixels are partly covered
    assert (alpha > 0.5).mean() > 0.005 and ((alpha > 0.05) & (alpha < 0.5)).mean() > 0.005


def test_billboards_show_their_sprite(physanim_ext, tmp_path):
    scene = _scene(tmp_path)
    sprite = bpy.data.images.new("Star", 8, 8, alpha=True)
    pixels = np.zeros((8, 8, 4), np.float32)
    pixels[..., 1] = 1.0  # green ...
    pixels[..., 3] = 1.0
    sprite.pixels.foreach_set(pixels.ravel())
    sprite.pack()
    ob = _baked(scene, 'BILLBOARD', sprite=sprite)
    ob.physanim.emitter.color_stops[0].color = (1.0, 1.0, 1.0, 1.0)
    for stop in ob.physanim.emitter.color_stops:
        stop.color = (1.0, 1.0, 1.0, 1.0)
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    scene.frame_set(FRAME)
    image = _render(scene, tmp_path / "sprite.exr")
    covered = image[..., 3] > 0.99  # ... and opaque: full squares, green
    assert covered.mean() > 0.005
    rgb = image[covered, :3]
    assert (rgb[:, 1] > 0.9).all() and (rgb[:, 0] < 0.05).all() and (rgb[:, 2] < 0.05).all()


def test_glowing_points_add_light_without_covering(physanim_ext, tmp_path):
    scene = _scene(tmp_path)
    scene.cycles.transparent_max_bounces = 256  # every glow a ray passes counts (see README)
    ob = _baked(scene, 'GLOW', glow_strength=0.5)
    res = ob.physanim.emitter.result
    points = result_points(res)
    pairs = _matched(points, _instances(res))
    assert len(pairs) == len(points["position"]) > 50
    camera = scene.camera.matrix_world.translation
    assert all(_faces_camera(m, camera) for _i, m in pairs)  # soft discs facing the camera
    dim = _render(scene, tmp_path / "dim.exr")
    ob.physanim.emitter.glow_strength = 1.0  # no re-bake: the setting applies at once
    bright = _render(scene, tmp_path / "bright.exr")
    assert dim[..., :3].sum() > 1.0
    assert bright[..., :3].sum() / dim[..., :3].sum() == pytest.approx(2.0, rel=0.02)
    assert bright[..., 3].max() < 0.02  # light only: nothing behind is hidden


def test_blobs_are_one_surface_around_the_points(physanim_ext, tmp_path):
    scene = _scene(tmp_path)
    ob = _baked(scene, 'BLOBS')
    p = ob.physanim.emitter
    res = p.result
    points = result_points(res)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    # a point cloud object whose geometry became a mesh: the depsgraph shows it as an instance
    (surface,) = [inst.object for inst in depsgraph.object_instances
                  if inst.is_instance and inst.parent.original == res]
    assert surface.type == 'MESH'
    mesh = surface.to_mesh()
    try:
        assert len(mesh.polygons) > 100
        co = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", co)
        co = co.reshape(-1, 3)
        colors = np.empty(len(mesh.vertices) * 4, np.float32)
        mesh.attributes["pa_color"].data.foreach_get("color", colors)
    finally:
        surface.to_mesh_clear()
    # every surface vertex lies about one blob radius from its nearest particle
    radius = p.blob_size * points["size"]
    distance = np.linalg.norm(co[:, None, :] - points["position"][None, :, :], axis=2)
    nearest = distance.argmin(axis=1)
    gap = distance[np.arange(len(co)), nearest] / radius[nearest]
    assert gap.max() < 1.2
    # coloured by the nearest particle
    np.testing.assert_allclose(colors.reshape(-1, 4), points["color"][nearest], atol=0.02)
    image = _render(scene, tmp_path / "blobs.exr")
    assert (image[..., 3] > 0.5).mean() > 0.01


def test_streaks_stretch_along_velocity(physanim_ext, tmp_path):
    scene = _scene(tmp_path)
    ob = _baked(scene, 'STREAKS')
    p = ob.physanim.emitter
    res = p.result
    points = result_points(res)
    pairs = _matched(points, _instances(res))
    assert len(pairs) == len(points["position"]) > 50
    long = 0
    for i, m in pairs:
        v, size = points["velocity"][i], points["size"][i]
        speed = np.linalg.norm(v)
        axis = m.to_3x3() @ Vector((0.0, 0.0, 1.0))
        assert axis.length == pytest.approx(size + speed * p.streak_time / 2, rel=1e-4)
        if speed > 1.0:
            assert abs(axis.normalized().dot(Vector(v / speed))) > 0.9999
            long += axis.length > 1.5 * size
        side = m.to_3x3() @ Vector((1.0, 0.0, 0.0))
        assert side.length == pytest.approx(size, rel=1e-4)
    assert long > 20
    image = _render(scene, tmp_path / "streaks.exr")
    assert (image[..., 3] > 0.5).mean() > 0.01


def test_render_as_changes_at_once_and_leaves_the_bake_alone(physanim_ext, tmp_path):
    scene = _scene(tmp_path)
    ob = _baked(scene, 'OBJECT', output='POINTS')  # the extension's output takes it too
    res = ob.physanim.emitter.result
    folder = Path(bpy.path.abspath(res.physanim.result.cache)).parent
    files = {f: f.stat().st_mtime_ns for f in folder.rglob("*") if f.is_file()}
    hash_before = scene.physanim.bake_hash
    panels = sys.modules[f"{physanim_ext.__name__}.addon.panels"]
    for mode, group in (('BILLBOARD', "physanim_billboards"), ('GLOW', "physanim_glow"),
                        ('BLOBS', "physanim_blobs"), ('STREAKS', "physanim_streaks"),
                        ('OBJECT', "physanim_instancer")):
        ob.physanim.emitter.render_as = mode
        assert res.modifiers["physanim_instances"].node_group.name == group
        assert (len(_instances(res)) > 0) == (mode != 'BLOBS')
    assert {f: f.stat().st_mtime_ns for f in folder.rglob("*") if f.is_file()} == files
    assert panels.bake_status(scene)[1] == 'CHECKMARK' and scene.physanim.bake_hash == hash_before


def test_blobs_with_no_points_and_a_crowd_of_fine_blobs(physanim_ext, tmp_path):
    """No particles (before the bake's frames): nothing, and no crash (Volume to Mesh of an
    empty volume crashes Blender 4.5, so no volume is made). A crowd at the finest Blob
    Resolution: the voxels grow coarser rather than filling memory."""
    scene = _scene(tmp_path)
    ob = _baked(scene, 'BLOBS', rate=200.0, blob_resolution=64.0)
    res = ob.physanim.emitter.result
    scene.frame_set(0)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    assert not [i for i in depsgraph.object_instances if i.is_instance and i.parent
                and i.parent.original == res]
    scene.frame_set(FRAME)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    (surface,) = [inst.object for inst in depsgraph.object_instances
                  if inst.is_instance and inst.parent.original == res]
    mesh = surface.to_mesh()
    try:
        assert 0 < len(mesh.vertices) < 5_000_000
    finally:
        surface.to_mesh_clear()
