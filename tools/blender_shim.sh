#!/usr/bin/env bash
# `blender -b FILE -c physanim ...` with the bpy module (see tools/blender_shim.py).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$("$here/tools/venv.sh" "${PHYSANIM_BLENDER:-4.5}")"
exec "$venv/bin/python" "$here/tools/blender_shim.py" "$@"
