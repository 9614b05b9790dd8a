#!/usr/bin/env bash
# The `blender -b -c physanim ...` commands with the bpy module (no blender binary needed).
# Usage: tools/physanim.sh bake shot.blend [--frames A-B] [--objects NAMES] [--save]
#        tools/physanim.sh free shot.blend [--save]        tools/physanim.sh --help
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$("$here/tools/venv.sh" "${PHYSANIM_BLENDER:-4.5}")"
exec "$venv/bin/python" "$here/tools/physanim.py" "$@"
