"""A stand-in for the ``blender`` executable where only the ``bpy`` module exists, for running
the farm job templates (``farm/``) locally: it takes the part of Blender's command line they use,

    blender_shim.py -b FILE.blend -c physanim COMMAND [ARGS...]

opens the file as ``-b`` does, then runs the ``-c physanim`` command with the extension loaded from
this source tree (as ``tools/physanim.py``), with the same log and exit code.
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tools import blender_env  # sets BLENDER_USER_RESOURCES before bpy is imported

import bpy


def main(argv: list[str]) -> int:
    blend = None
    if argv[:1] == ["-b"] and len(argv) > 1 and argv[1].endswith(".blend"):
        blend, argv = argv[1], argv[2:]
    if argv[:2] != ["-c", "physanim"]:
        print("blender_shim: usage: -b FILE.blend -c physanim COMMAND [ARGS...]", file=sys.stderr)
        return 2
    module = blender_env.enable_extension()
    try:
        if blend is not None:
            bpy.ops.wm.open_mainfile(filepath=blend)
        return module.addon.cli.main(argv[2:])
    finally:
        blender_env.disable_extension()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
