"""Blender layer of PhysAnim: the only code that imports bpy.

Submodules register in a fixed order; unregister runs it backwards and removes every handler the
add-on added (Blender 4.2 crashes and 4.5 hangs at exit when Python handlers stay registered).
"""
from __future__ import annotations

import importlib

_MODULES = ("props", "ops", "connect", "panels", "results", "cli")


def _modules():
    return [importlib.import_module(f"{__name__}.{name}") for name in _MODULES]


def register() -> None:
    for module in _modules():
        module.register()


def unregister() -> None:
    for module in reversed(_modules()):
        module.unregister()
