#!/usr/bin/env bash
# Benchmarks: physanim against Blender's built-in particle system (same scene, same process) and
# the core solver's cost per particle-step. Prints markdown tables; asserts no timings.
# Usage: tools/bench.sh [--quick] [--count N] [--frames F] [--profile] [--help]
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$("$here/tools/venv.sh" "${PHYSANIM_BLENDER:-4.5}")"
cd "$here"
exec "$venv/bin/python" bench/particles.py "$@"
