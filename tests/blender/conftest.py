"""Headless Blender fixtures: the extension is built into its zip with Blender's packaging tool
and installed + enabled by Blender's extension installer, as a user installing it would."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from tools import blender_env  # sets BLENDER_USER_RESOURCES before bpy is imported

bpy = pytest.importorskip("bpy")


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
    module = blender_env.install_package()
    yield module
    blender_env.disable_extension(module.__name__)
    # Drop only handlers added since the baseline; clearing everything breaks Cycles at exit.
    for name, handlers in _handler_lists().items():
        keep = baseline.get(name, [])
        handlers[:] = [h for h in handlers if any(h is k for k in keep)]


@pytest.fixture(autouse=True)
def empty_scene():
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    yield bpy.context.scene
