import sys

import bpy


def test_extension_is_enabled_through_the_extension_system(physanim_ext):
    assert physanim_ext.__name__ == "bl_ext.physanim_dev.physanim"
    assert physanim_ext.__name__ in {a.module for a in bpy.context.preferences.addons}
    assert sys.modules[physanim_ext.__name__ + ".addon"]
