"""Imports go one way (addon -> core): the core loads in a plain interpreter without Blender."""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

CORE_MODULES = [
    "physanim.core", "physanim.core.errors", "physanim.core.curves", "physanim.core.transforms",
    "physanim.core.cache", "physanim.core.integrators", "physanim.core.particles",
    "physanim.core.particles.solver", "physanim.core.particles.output",
]
BLENDER_MODULES = ("bpy", "mathutils", "bmesh", "gpu", "bgl", "blf", "bpy_extras", "_bpy")


def test_core_imports_without_blender_modules():
    script = textwrap.dedent(f"""
        import importlib, importlib.util, json, sys
        root = {str(ROOT)!r}
        spec = importlib.util.spec_from_file_location(
            "physanim", root + "/__init__.py", submodule_search_locations=[root])
        module = importlib.util.module_from_spec(spec)
        sys.modules["physanim"] = module
        spec.loader.exec_module(module)
        for name in {CORE_MODULES!r}:
            importlib.import_module(name)
        print(json.dumps(sorted(sys.modules)))
    """)
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                            timeout=120, cwd=str(ROOT.parent))
    assert result.returncode == 0, result.stderr
    loaded = set(json.loads(result.stdout.strip().splitlines()[-1]))
    for name in CORE_MODULES:
        assert name in loaded
    blender = sorted(m for m in loaded if m.split(".")[0] in BLENDER_MODULES)
    assert blender == [], f"core pulled in Blender modules: {blender}"
    addon = sorted(m for m in loaded if m.startswith("physanim.addon"))
    assert addon == [], f"core imported addon modules: {addon}"
