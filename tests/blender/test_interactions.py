"""Interactions among particles from Blender: a force object of type Mutual Gravity,
Lennard-Jones or Coulomb, at its defaults, changes a default emitter's particles; its Emitters
collection says whose particles take part; its values are keyframable; a too-stiff setting
stops the bake with the sub-steps it needs."""
from __future__ import annotations

import sys
from pathlib import Path

import bpy
import numpy as np
import pytest


def _scene(tmp_path: Path, end: int = 20):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    scene.physanim.frame_start, scene.physanim.frame_end = 1, end
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "interact.blend"))
    return scene


def _emitter(name: str, location=(0.0, 0.0, 0.0)):
    ob = bpy.data.objects.new(name, None)
    bpy.context.scene.collection.objects.link(ob)
    ob.location = location
    ob.physanim.emitter.enabled = True
    return ob


def _force(kind: str):
    ob = bpy.data.objects.new(kind.title(), None)
    bpy.context.scene.collection.objects.link(ob)
    ob.physanim.force.enabled = True
    ob.physanim.force.type = kind
    return ob


def _positions(ext, ob, frame: int) -> np.ndarray:
    cache = sys.modules[f"{ext.__name__}.core.cache"]
    folder = bpy.path.abspath(ob.physanim.emitter.result.physanim.result.cache)
    arrays = cache.read_frame(folder, frame)
    return arrays["position"][np.argsort(arrays["id"])].astype(float)


def _bake_positions(ext, ob, frame: int = 20) -> np.ndarray:
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    return _positions(ext, ob, frame)


@pytest.mark.parametrize("kind", ["GRAVITY", "LENNARD_JONES", "COULOMB"])
def test_each_interaction_at_its_defaults_bakes_with_a_default_emitter(physanim_ext, tmp_path,
                                                                      kind):
    """Only the force object (its type chosen) and a default emitter: the bake runs at the
    default sub-steps; gravity and Lennard-Jones move the particles, Coulomb moves them once
    the emitter has a charge (uncharged particles feel none)."""
    _scene(tmp_path)
    spout = _emitter("Spout")
    plain = _bake_positions(physanim_ext, spout)
    force = _force(kind)
    if kind == 'GRAVITY':
        force.physanim.force.gravity_constant = 50.0  # the default 1 pulls 0.1 kg by microns
    moved = _bake_positions(physanim_ext, spout)
    assert len(moved) == len(plain) > 100 and np.isfinite(moved).all()
    if kind == 'COULOMB':
        assert np.array_equal(moved, plain)
        spout.physanim.emitter.charge = 0.5
        moved = _bake_positions(physanim_ext, spout)
    assert np.abs(moved - plain).max() > 1e-3


def test_only_the_emitters_in_its_collection_interact(physanim_ext, tmp_path):
    """The force's Emitters collection holds one emitter: the other's particles are exactly
    as without the force; gravity among two emitters pulls their streams together."""
    _scene(tmp_path)
    left, right = _emitter("Left", (-1.0, 0.0, 0.0)), _emitter("Right", (1.0, 0.0, 0.0))
    plain_left = _bake_positions(physanim_ext, left)
    plain_right = _positions(physanim_ext, right, 20)
    force = _force('GRAVITY')
    force.physanim.force.gravity_constant = 200.0
    group = bpy.data.collections.new("Stars")
    group.objects.link(left)
    force.physanim.force.affects = group
    pulled_left = _bake_positions(physanim_ext, left)
    assert np.array_equal(_positions(physanim_ext, right, 20), plain_right)
    assert np.abs(pulled_left - plain_left).max() > 1e-3
    group.objects.link(right)  # both: the streams pull towards each other
    both_left = _bake_positions(physanim_ext, left)
    assert both_left[:, 0].mean() > pulled_left[:, 0].mean()


def test_interaction_values_are_keyframable(physanim_ext, tmp_path):
    """G keyed from 0 to 100 over the bake: the result differs from G held at 0 (no pull) and
    from G held at 100."""
    _scene(tmp_path)
    spout = _emitter("Spout")
    force = _force('GRAVITY')
    p = force.physanim.force
    results = {}
    for label, keys in (("zero", ((1, 0.0),)), ("full", ((1, 100.0),)),
                        ("ramp", ((1, 0.0), (20, 100.0)))):
        if force.animation_data:
            force.animation_data_clear()
        for frame, value in keys:
            p.gravity_constant = value
            p.keyframe_insert("gravity_constant", frame=frame)
        results[label] = _bake_positions(physanim_ext, spout)
    assert not np.array_equal(results["ramp"], results["zero"])
    assert not np.array_equal(results["ramp"], results["full"])


def test_a_too_stiff_lennard_jones_names_the_substeps_it_needs(physanim_ext, tmp_path):
    _scene(tmp_path)
    _emitter("Spout")
    force = _force('LENNARD_JONES')
    force.physanim.force.epsilon = 0.05
    with pytest.raises(RuntimeError, match=r"force \"Lennard_Jones\" at frame \d+: too stiff.*"
                                           r"Substeps to \d+"):
        bpy.ops.physanim.bake()


def test_particle_collisions_at_their_defaults_keep_particles_apart(physanim_ext, tmp_path):
    """Particle Collisions and nothing else beside a default emitter and a default ground:
    the particles come to rest on the ground side by side — no two resting particles overlap
    by more than 1 % of their size, where without it they sit inside each other."""
    _scene(tmp_path, 90)
    bpy.ops.mesh.primitive_plane_add(size=20.0)
    bpy.context.object.physanim.collider.enabled = True
    spout = _emitter("Spout", (0.0, 0.0, 1.0))
    size = spout.physanim.emitter.size
    cache = sys.modules[f"{physanim_ext.__name__}.core.cache"]

    def worst_overlap(frame: int, resting: bool) -> float:
        folder = bpy.path.abspath(spout.physanim.emitter.result.physanim.result.cache)
        arrays = cache.read_frame(folder, frame)
        keep = arrays["age"] >= 1.0  # the last frame's newborn leave the nozzle together
        if resting:
            keep &= np.linalg.norm(arrays["velocity"], axis=1) < 0.05
        x = arrays["position"][keep].astype(float)
        assert len(x) > 20
        d = np.linalg.norm(x[:, None] - x[None], axis=2) + np.eye(len(x)) * 1e9
        return (2 * size - d.min()) / size

    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert worst_overlap(90, resting=False) > 0.5
    _force('COLLISIONS')
    assert bpy.ops.physanim.bake() == {'FINISHED'}
    assert worst_overlap(90, resting=True) < 0.01
