#!/usr/bin/env bash
# Build the installable extension zip with Blender's own packaging tool and list it in an
# index.json beside it, so OUT_DIR is also a static extension repository (file:// or HTTP).
# Usage: tools/build.sh [OUT_DIR]      (default dist/; prints the zip's path)
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$("$here/tools/venv.sh" "${PHYSANIM_BLENDER:-4.5}")"
out="$(mkdir -p "${1:-$here/dist}" && cd "${1:-$here/dist}" && pwd)"
rm -f "$out"/physanim-*.zip  # one zip: the one just built
cd "$here"
exec "$venv/bin/python" -c "
import sys
sys.path.insert(0, '.')
from tools import blender_env
print(blender_env.build_repository(sys.argv[1]))" "$out"
