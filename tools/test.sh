#!/usr/bin/env bash
# Run the test suite in headless Blender (the `bpy` module). Sets up its own venv when missing.
# Usage: tools/test.sh [pytest args...]      PHYSANIM_BLENDER=4.2|4.5|5.0 picks the Blender build.
# Tests run in one worker process per core (pytest-xdist; each worker is its own headless Blender);
# PHYSANIM_TEST_WORKERS=N sets the number, 0 runs everything in this process (for -s / pdb).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$("$here/tools/venv.sh" "${PHYSANIM_BLENDER:-4.5}")"
cd "$here"
# each worker's BLAS on its own thread: the workers already keep every core busy, and OpenBLAS's
# threads would wait for one (a bake sets this itself while it runs: addon/blas.py)
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"
workers="${PHYSANIM_TEST_WORKERS:-auto}"
parallel=()
if [ "$workers" != 0 ]; then parallel=(-n "$workers" --dist worksteal); fi
exec "$venv/bin/python" -m pytest -p no:cacheprovider "${parallel[@]}" "${@:-tests}"
