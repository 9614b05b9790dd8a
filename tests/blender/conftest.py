"""Headless Blender fixtures: the extension is installed and enabled the way Blender does it.

A user-type extension repository is created in a temp folder holding a symlink ``physanim`` to the
source tree, then ``addon_utils.enable("bl_ext.physanim_dev.physanim")`` runs the manifest-based
extension loader — the same code path as an installed extension, running the sources in place.
"""
from __future__ import annotations

import os
import sys
import tempfile

import pytest

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

bpy = pytest.importorskip("bpy")
import addon_utils  # noqa: E402  (needs bpy first)

REPO_MODULE = "physanim_dev"
MODULE = f"bl_ext.{REPO_MODULE}.physanim"


def _handler_lists() -> dict[str, list]:
    lists = {}
    for name in dir(bpy.app.handlers):
        value = getattr(bpy.app.handlers, name)
        if isinstance(value, list):
            lists[name] = value
    return lists


@pytest.fixture(scope="session", autouse=True)
def physanim_ext():
    baseline = {n: list(handlers) for n, handlers in _handler_lists().items()}
    repo_dir = tempfile.mkdtemp(prefix="physanim_repo_")
    os.symlink(ROOT, os.path.join(repo_dir, "physanim"))
    repos = bpy.context.preferences.extensions.repos
    if REPO_MODULE not in {r.module for r in repos}:
        repos.new(name=REPO_MODULE, module=REPO_MODULE, custom_directory=repo_dir, source='USER')
    addon_utils.enable(MODULE, default_set=True, handle_error=None)
    assert MODULE in sys.modules, "the physanim extension did not load"
    yield sys.modules[MODULE]
    addon_utils.disable(MODULE, default_set=True)
    # Drop only handlers added since the baseline; clearing everything breaks Cycles at exit.
    for name, handlers in _handler_lists().items():
        keep = baseline.get(name, [])
        handlers[:] = [h for h in handlers if any(h is k for k in keep)]


@pytest.fixture(autouse=True)
def empty_scene():
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    yield bpy.context.scene
