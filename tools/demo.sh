#!/usr/bin/env bash
# Main job: bake the sample scenes headless, save each as a .blend and render previews.
# Usage: tools/demo.sh [--out OUT] [--scenes fountain,fireworks,robot_arm] [--frames 40,80]
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$("$here/tools/venv.sh" "${PHYSANIM_BLENDER:-4.5}")"
cd "$here"
exec "$venv/bin/python" tools/demo.py "$@"
