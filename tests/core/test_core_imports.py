"""Imports go one way (addon -> core): every core module loads in a plain interpreter without
Blender, and no system package (particles, springs, ...) imports another: they meet in the
shared packages (contact, forces, collision) and in the caller."""
from __future__ import annotations

import ast
import json
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CORE = ROOT / "core"
BLENDER_MODULES = ("bpy", "mathutils", "bmesh", "gpu", "bgl", "blf", "bpy_extras", "_bpy")
SYSTEMS = ("particles", "springs", "rigid", "constraints")  # packages that must not meet directly


def _core_modules() -> list[str]:
    names = []
    for path in sorted(CORE.rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        names.append(".".join(("physanim", *parts)))
    return names


def test_every_core_module_imports_without_blender_or_addon():
    modules = _core_modules()
    assert {"physanim.core.springs.solver", "physanim.core.pc2", "physanim.core.contact.mesh",
            "physanim.core.forces.fields"} <= set(modules)
    script = textwrap.dedent(f"""
        import importlib, importlib.util, json, sys
        root = {str(ROOT)!r}
        spec = importlib.util.spec_from_file_location(
            "physanim", root + "/__init__.py", submodule_search_locations=[root])
        module = importlib.util.module_from_spec(spec)
        sys.modules["physanim"] = module
        spec.loader.exec_module(module)
        for name in {modules!r}:
            importlib.import_module(name)
        print(json.dumps(sorted(sys.modules)))
    """)
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                            timeout=120, cwd=str(ROOT.parent))
    assert result.returncode == 0, result.stderr
    loaded = set(json.loads(result.stdout.strip().splitlines()[-1]))
    assert set(modules) <= loaded
    blender = sorted(m for m in loaded if m.split(".")[0] in BLENDER_MODULES)
    assert blender == [], f"core pulled in Blender modules: {blender}"
    addon = sorted(m for m in loaded if m.startswith("physanim.addon"))
    assert addon == [], f"core imported addon modules: {addon}"


def _imported(path: Path) -> set[str]:
    """Absolute dotted names (below physanim.core) that a core module imports."""
    package = path.relative_to(CORE).parent.parts
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            base = list(package[:len(package) - node.level + 1])
            target = base + (node.module.split(".") if node.module else [])
            out.update(".".join(target + [a.name]) for a in node.names)
            out.add(".".join(target))
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module]
            out.update(n.removeprefix("physanim.core.") for n in names
                       if n and n.startswith("physanim.core."))
    return out


def test_no_system_package_imports_another():
    crossings = []
    for path in sorted(CORE.rglob("*.py")):
        own = path.relative_to(CORE).parts[0]
        for name in _imported(path):
            other = name.split(".")[0]
            if own in SYSTEMS and other in SYSTEMS and other != own:
                crossings.append(f"{path.relative_to(ROOT)} imports {name}")
    assert crossings == []
