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
