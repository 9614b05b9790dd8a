#!/usr/bin/env bash
# Run the test suite in headless Blender (the `bpy` module). Sets up its own venv when missing.
# Usage: tools/test.sh [pytest args...]      PHYSANIM_BLENDER=4.2|4.5|5.0 picks the Blender build.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$("$here/tools/venv.sh" "${PHYSANIM_BLENDER:-4.5}")"
cd "$here"
exec "$venv/bin/python" -m pytest -p no:cacheprovider "${@:-tests}"
