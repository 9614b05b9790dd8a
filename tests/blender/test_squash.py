"""Squash and stretch in Blender: rigid bodies get scale keys and particle instances an instance
transform that stretch along the motion and squash on impact, the volume kept to 1e-6, while
the simulation (every position) is exactly what it is without."""
from __future__ import annotations

import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

FRAMES = 48


def _scene(tmp_path: Path):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    scene.physanim.frame_start, scene.physanim.frame_end = 1, FRAMES
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "squash.blend"))
    bpy.ops.mesh.primitive_plane_add(size=20.0)
    bpy.context.object.physanim.collider.enabled = True
    return scene


def _frames(folder: Path) -> list[bytes]:
    return [p.read_bytes() for p in sorted(folder.rglob("frame_*.npz"))]


def _euler_matrix(e: np.ndarray) -> np.ndarray:
    x, y, z = e.T
    c, s = np.cos, np.sin
    one, zero = np.ones_like(x), np.zeros_like(x)
    rx = np.stack([one, zero, zero, zero, c(x), -s(x), zero, s(x), c(x)], 1).reshape(-1, 3, 3)
    ry = np.stack([c(y), zero, s(y), zero, one, zero, -s(y), zero, c(y)], 1).reshape(-1, 3, 3)
    rz = np.stack([c(z), -s(z), zero, s(z), c(z), zero, zero, zero, one], 1).reshape(-1, 3, 3)
    return rz @ ry @ rx


def test_a_rigid_box_stretches_as_it_falls_and_squashes_as_it_lands(physanim_ext, tmp_path):
    scene = _scene(tmp_path)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, 4.0))
    box = bpy.context.object
    box.scale = (1.0, 1.0, 0.5)
    p = box.physanim.rigid_body
    p.enabled = True
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    folder = Path(bpy.path.abspath(scene.physanim.cache_dir))
    plain = _frames(folder)
    heights = []
    for frame in range(1, FRAMES + 1):
        scene.frame_set(frame)
        heights.append(box.matrix_world.translation.z)
    assert tuple(box.scale) == pytest.approx((1.0, 1.0, 0.5))  # no squash keys: off

    p.squash = 1.0  # nothing else set
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert _frames(folder) == plain  # the simulation is exactly the same
    factors, z = [], []
    for frame in range(1, FRAMES + 1):
        scene.frame_set(frame)
        factors.append(np.array(box.scale) / (1.0, 1.0, 0.5))
        z.append(box.matrix_world.translation.z)
    factors = np.array(factors)
    np.testing.assert_allclose(z, heights, atol=1e-6)  # and so is where it is
    np.testing.assert_allclose(np.prod(factors, axis=1), 1.0, atol=1e-6)  # volume kept
    landing = int(np.argmax(np.diff(heights) > -1e-3 + 0.0 * np.arange(len(heights) - 1)))
    falling = slice(3, landing - 1)
    assert (factors[falling, 2] > 1.0).all()  # stretched along the fall
    impact = landing + 1  # the frame after it stopped falling
    assert factors[landing:impact + 1, 2].min() < 0.9  # squashed flat on landing
    assert abs(factors[-1, 2] - 1.0) < 0.01  # recovered, at rest
    assert bpy.ops.physanim.free_bake() == {'FINISHED'}
    assert tuple(box.scale) == pytest.approx((1.0, 1.0, 0.5))


def test_particle_instances_squash_on_the_ground_and_keep_their_volume(physanim_ext, tmp_path):
    _scene(tmp_path)
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(0.0, 0.0, 3.0))
    emitter = bpy.context.object
    p = emitter.physanim.emitter
    p.enabled = True
    cache = sys.modules[f"{physanim_ext.__name__}.core.cache"]
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    folder = Path(bpy.path.abspath(p.result.physanim.result.cache))
    plain = {f: cache.read_frame(folder, f) for f in range(1, FRAMES + 1)}

    p.squash = 1.0  # nothing else set
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    squashed_seen = 0
    landed: set[int] = set()  # ids that have hit the ground (their squash is still fading)
    for frame in range(1, FRAMES + 1):
        a = cache.read_frame(folder, frame)
        for key in ("id", "position", "velocity", "age", "size", "color"):
            np.testing.assert_array_equal(a[key], plain[frame][key])  # the motion is as it was
        scale = a["instance_scale"] / a["size"][:, None]
        np.testing.assert_allclose(np.prod(scale, axis=1), 1.0, atol=1e-6)
        S = _euler_matrix(a["instance_rotation"].astype(np.float64)) @ (
            scale[:, :, None] * np.swapaxes(_euler_matrix(
                a["instance_rotation"].astype(np.float64)), 1, 2))
        speed = np.linalg.norm(a["velocity"], axis=1)
        if frame > 1:
            before = plain[frame - 1]
            _, i, j = np.intersect1d(before["id"], a["id"], return_indices=True)
            turned = before["velocity"][i, 2] < 0.0
            turned &= a["velocity"][j, 2] - before["velocity"][i, 2] > 1.0
            landed |= set(a["id"][j[turned]].tolist())
        never = ~np.isin(a["id"], list(landed))
        flying = (speed > 3.0) & never
        if flying.any():  # stretched along the velocity (nothing hit yet)
            d = a["velocity"][flying] / speed[flying, None]
            along = np.einsum("ni,nij,nj->n", d, S[flying], d)
            np.testing.assert_allclose(along, np.exp(0.02 * speed[flying]), rtol=1e-4)
        if frame > 1:
            before = plain[frame - 1]
            common, i, j = np.intersect1d(before["id"], a["id"], return_indices=True)
            bounced = (before["velocity"][i, 2] < -2.0) & (a["velocity"][j, 2] > 0.0)
            if bounced.any():
                assert (S[j[bounced], 2, 2] < 0.95).all()  # flattened along the ground normal
                squashed_seen += int(bounced.sum())
    assert squashed_seen > 20
