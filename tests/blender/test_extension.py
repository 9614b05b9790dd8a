import sys

import bpy


def test_extension_is_installed_from_its_package_and_enabled(physanim_ext):
    assert physanim_ext.__name__ == "bl_ext.physanim_test.physanim"
    assert physanim_ext.__name__ in {a.module for a in bpy.context.preferences.addons}
    installed = physanim_ext.__file__
    assert "physanim_repo_" in installed  # the unpacked package, not the source tree
    assert sys.modules[physanim_ext.__name__ + ".addon"]
    assert hasattr(bpy.ops.physanim, "bake") and hasattr(bpy.ops.physanim, "free_bake")
    assert hasattr(bpy.types.Scene, "physanim") and hasattr(bpy.types.Object, "physanim")


def test_package_leaves_out_tests_and_sample_scenes(physanim_ext):
    import os

    root = os.path.dirname(physanim_ext.__file__)
    names = set(os.listdir(root))
    assert {"blender_manifest.toml", "core", "addon", "__init__.py"} <= names
    farm = set(os.listdir(os.path.join(root, "farm", "openjd")))
    assert {"physanim_shot.yaml", "physanim_wedge.yaml"} <= farm  # the farm job templates ship
    assert not names & {"tests", "sample_scenes", "tools", ".ci", "pytest.ini"}


def test_disabling_removes_every_handler(physanim_ext):
    import addon_utils

    ours = lambda: [h for name in ("frame_change_pre", "load_post")  # noqa: E731
                    for h in getattr(bpy.app.handlers, name)
                    if getattr(h, "__module__", "").startswith(physanim_ext.__name__)]
    assert ours()
    addon_utils.disable(physanim_ext.__name__, default_set=True)
    try:
        assert ours() == []
    finally:
        addon_utils.enable(physanim_ext.__name__, default_set=True, handle_error=None)
    assert ours()


def test_per_frame_properties_are_keyframable_and_static_ones_are_not(physanim_ext):
    """Everything the extract step samples per frame can be keyed; what a bake reads once
    (topology, seeds, curve stops, solver settings) cannot, so no key silently does nothing."""
    ob = bpy.data.objects.new("E", None)
    bpy.context.scene.collection.objects.link(ob)
    ob.physanim.emitter.enabled = True
    for path in ("rate", "rate_random", "lifetime", "speed", "spread", "inherit_velocity", "mass",
                 "size", "frame_start", "frame_end"):
        assert ob.keyframe_insert(f"physanim.emitter.{path}", frame=1), path
    for path in ("physanim.collider.restitution", "physanim.collider.friction",
                 "physanim.force.strength", "physanim.force.noise"):
        assert ob.keyframe_insert(path, frame=1), path
    emitter_rna = type(ob.physanim.emitter).bl_rna.properties
    for name in ("source", "direction", "seed", "stretch", "link_stiffness", "output"):
        assert not emitter_rna[name].is_animatable, name
    stop_rna = type(ob.physanim.emitter.color_stops[0]).bl_rna.properties
    assert not stop_rna["color"].is_animatable and not stop_rna["position"].is_animatable
    scene_rna = type(bpy.context.scene.physanim).bl_rna.properties
    for name in ("frame_start", "frame_end", "substeps", "integrator", "tolerance", "seed"):
        assert not scene_rna[name].is_animatable, name
