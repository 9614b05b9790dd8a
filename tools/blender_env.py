"""Run PhysAnim inside the `bpy` module the way Blender does: as an enabled extension.

A user extension repository is created in a temp folder holding a symlink ``physanim`` to the
source tree; ``addon_utils.enable("bl_ext.physanim_dev.physanim")`` then runs the manifest-based
extension loader, exactly as for an installed extension, on the sources in place.
Import this module before ``bpy``: it points ``BLENDER_USER_RESOURCES`` at a temp folder so
nothing is written to $HOME.
"""
from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
REPO_MODULE = "physanim_dev"
MODULE = f"bl_ext.{REPO_MODULE}.physanim"

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="physanim_bl_user_"))


def enable_extension():
    """Enable PhysAnim as an extension and return its module."""
    import addon_utils
    import bpy

    if MODULE in sys.modules and MODULE in bpy.context.preferences.addons:
        return sys.modules[MODULE]
    repos = bpy.context.preferences.extensions.repos
    if REPO_MODULE not in {r.module for r in repos}:
        repo_dir = tempfile.mkdtemp(prefix="physanim_repo_")
        os.symlink(ROOT, os.path.join(repo_dir, "physanim"))
        repos.new(name=REPO_MODULE, module=REPO_MODULE, custom_directory=repo_dir, source='USER')
    addon_utils.enable(MODULE, default_set=True, handle_error=None)
    if MODULE not in sys.modules:
        raise RuntimeError("the physanim extension did not load")
    return sys.modules[MODULE]


def disable_extension() -> None:
    """Disable the extension: its unregister removes every handler it added (Blender 4.2
    crashes and 4.5 hangs at exit when Python handlers stay registered)."""
    import addon_utils

    addon_utils.disable(MODULE, default_set=True)
