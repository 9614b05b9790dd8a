"""Run a ``-c physanim`` command with the ``bpy`` module, where there is no ``blender`` binary:

    python tools/physanim.py bake shot.blend --frames 1-250 --save

is ``blender -b -c physanim bake shot.blend --frames 1-250 --save`` (same arguments, same log,
same exit code), with the extension loaded from this source tree.
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tools import blender_env  # sets BLENDER_USER_RESOURCES before bpy is imported

import bpy  # noqa: F401  (Blender's Python modules, addon_utils among them, come with it)


def main(argv: list[str]) -> int:
    module = blender_env.enable_extension()
    try:
        return module.addon.cli.main(argv)
    finally:
        # the extension's handlers must go before the interpreter exits (guide: 4.2 crashes,
        # 4.5 hangs at exit with Python handlers still registered)
        blender_env.disable_extension()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
