#!/usr/bin/env bash
# Random-scene fuzzing of the bake (see tools/fuzz.py). Prints one line per scene and a tally;
# exits non-zero when any scene let an exception escape, wrote a non-finite value, failed
# without naming an object, or lost a previous bake.
# Usage: tools/fuzz.sh [COUNT] [FIRST_SEED]      (default: 200 scenes from seed 0)
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$("$here/tools/venv.sh" "${PHYSANIM_BLENDER:-4.5}")"
cd "$here"
exec "$venv/bin/python" tools/fuzz.py "$@"
