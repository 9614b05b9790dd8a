"""A million particles through the result path, and the pre-bake size estimate."""
from __future__ import annotations

import importlib

import bpy
import numpy as np
import pytest


def _mod(ext, name):
    return importlib.import_module(f"{ext.__name__}.{name}")


def test_result_object_shows_a_million_particles_per_frame(physanim_ext, tmp_path):
    """A 1M-particle cache frame reaches the points object and its instances on frame change."""
    cache = _mod(physanim_ext, "core.cache")
    results = _mod(physanim_ext, "addon.results")
    scene = bpy.context.scene
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "big.blend"))
    scene = bpy.context.scene
    emitter = bpy.data.objects.new("Big", None)
    scene.collection.objects.link(emitter)
    emitter.physanim.emitter.enabled = True
    n = 1_000_000
    rng = np.random.default_rng(0)
    writer = cache.CacheWriter(tmp_path / "physanim_cache" / "Big")
    for frame, count in ((1, n), (2, n // 2)):
        writer.write_frame("points", frame, {
            "id": np.arange(count, dtype=np.int32) + frame,
            "position": rng.normal(size=(count, 3)).astype(np.float32),
            "velocity": np.zeros((count, 3), np.float32),
            "age": np.full(count, frame, np.float32),
            "size": np.full(count, 0.01, np.float32),
            "color": np.ones((count, 4), np.float32),
        })
    path = writer.commit({"kind": "particles"})
    emitter.physanim.emitter.output = 'POINTS'  # the extension's mesh, loaded per frame change
    results.attach(bpy.context, scene, emitter, "//physanim_cache/Big/points", 1, 2)
    res = emitter.physanim.emitter.result
    for frame, count in ((1, n), (2, n // 2), (1, n), (3, 0)):
        scene.frame_set(frame)
        assert len(res.data.vertices) == count
        if count:
            ids = np.empty(count, np.int32)
            res.data.attributes["id"].data.foreach_get("value", ids)
            expected = cache.read_frame(path / "points", frame)["id"]
            assert np.array_equal(ids, expected)
    scene.frame_set(1)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    instances = sum(1 for inst in depsgraph.object_instances
                    if inst.is_instance and inst.parent and inst.parent.original == res)
    assert instances == n


def test_bake_refuses_a_scene_that_cannot_fit_in_memory(physanim_ext, tmp_path):
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "huge.blend"))
    scene = bpy.context.scene
    emitter = bpy.data.objects.new("Huge", None)
    scene.collection.objects.link(emitter)
    p = emitter.physanim.emitter
    p.enabled = True
    p.rate, p.lifetime, p.frame_end = 1.0e6, 1.0e5, 250
    scene.physanim.frame_end = 250
    with pytest.raises(RuntimeError, match=r"estimated [\d,]+ particles alive at once need about"):
        bpy.ops.physanim.bake()
    assert emitter.physanim.emitter.result is None
    assert not (tmp_path / "physanim_cache").exists() or not any((tmp_path / "physanim_cache").rglob("*.npz"))
