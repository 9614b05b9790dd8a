"""Test session setup shared by the core and Blender suites.

The repository root is the ``physanim`` package. Its directory may have any name on disk, so the
package is registered under ``physanim`` by path: core tests then ``import physanim.core``.
"""
from __future__ import annotations

import importlib.util
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# Blender writes its config, extensions and preferences under this folder instead of $HOME.
# Each pytest-xdist worker is its own Blender and installs the extension: it gets its own folder
# (the workers inherit the controller's environment, so the controller's folder would be shared).
if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="physanim_bl_user_")
else:
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="physanim_bl_user_"))


def _register_package_by_path() -> None:
    if "physanim" in sys.modules:
        return
    spec = importlib.util.spec_from_file_location(
        "physanim", ROOT / "__init__.py", submodule_search_locations=[str(ROOT)]
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules["physanim"] = module
    spec.loader.exec_module(module)


_register_package_by_path()
