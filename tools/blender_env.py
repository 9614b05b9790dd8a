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


def build_package(out_dir: str) -> str:
    """Build the extension zip with Blender's own packaging tool; returns the zip's path."""
    import subprocess

    import bpy

    tool = os.path.join(bpy.utils.resource_path('LOCAL'),
                        "scripts/addons_core/bl_pkg/cli/blender_ext.py")
    os.makedirs(out_dir, exist_ok=True)
    done = subprocess.run([sys.executable, tool, "build", "--source-dir", str(ROOT),
                           "--output-dir", out_dir], capture_output=True, text=True)
    zips = [f for f in os.listdir(out_dir) if f.endswith(".zip")]
    if done.returncode != 0 or len(zips) != 1:
        raise RuntimeError(f"extension build failed:\n{done.stdout}\n{done.stderr}")
    return os.path.join(out_dir, zips[0])


def build_repository(out_dir: str) -> str:
    """Build the zip into ``out_dir`` and list it in an ``index.json`` there (Blender's
    ``server-generate``): the folder is then a static extension repository, to be added in
    Preferences > Get Extensions > Repositories as ``file:///<out_dir>/index.json`` or served over
    HTTP. Returns the zip's path."""
    import bpy  # noqa: F401  (Blender's bl_pkg comes with it)
    import bl_pkg

    zip_path = build_package(out_dir)
    try:
        bl_pkg.cli_extension(["server-generate", "--repo-dir", out_dir])
    except SystemExit as exc:  # the command-line tool exits; 0 is success
        if exc.code:
            raise RuntimeError(f"server-generate failed in {out_dir} (exit {exc.code})") from exc
    if not os.path.isfile(os.path.join(out_dir, "index.json")):
        raise RuntimeError(f"server-generate wrote no index.json in {out_dir}")
    return zip_path


def install_package(repo_module: str = "physanim_test"):
    """Build the zip and install it into a fresh user repository with Blender's installer (as
    Extensions > Install from Disk does); returns the enabled module."""
    import bpy

    module = f"bl_ext.{repo_module}.physanim"
    zip_path = build_package(tempfile.mkdtemp(prefix="physanim_dist_"))
    repos = bpy.context.preferences.extensions.repos
    if repo_module not in {r.module for r in repos}:
        repos.new(name=repo_module, module=repo_module,
                  custom_directory=tempfile.mkdtemp(prefix="physanim_repo_"), source='USER')
    # Returns {'FINISHED'} even on failure (guide §1): check the module instead.
    bpy.ops.extensions.package_install_files(filepath=zip_path, repo=repo_module,
                                             enable_on_install=True)
    if module not in sys.modules:
        raise RuntimeError(f"installing {zip_path} did not enable {module}")
    return sys.modules[module]


def disable_extension(module: str = MODULE) -> None:
    """Disable the extension: its unregister removes every handler it added (Blender 4.2
    crashes and 4.5 hangs at exit when Python handlers stay registered)."""
    import addon_utils

    addon_utils.disable(module, default_set=True)
