#!/usr/bin/env bash
# Benchmarks: physanim against Blender's built-in particle system (same scene, same process) and
# the core solver's cost per particle-step. Prints markdown tables; asserts no timings.
# Usage: tools/bench.sh [particles] [--quick] [--count N] [--frames F] [--profile] [--help]
#        tools/bench.sh cloth [--frames F] [--grid N]      tools/bench.sh broadphase [--quick]
#        tools/bench.sh cloth-self [--frames F] [--grid N]
#        tools/bench.sh rigid [--cubes N] [--frames F] [--stack N]
#        tools/bench.sh chain [--links N] [--frames F]
#        tools/bench.sh interactions [--quick] [--sizes N,N] [--theta T]
#        tools/bench.sh sph [--count N] [--frames F] [--emit F]
#        tools/bench.sh heap [--grains N] [--frames F] [--friction MU,MU] [--seeds S,S]
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$("$here/tools/venv.sh" "${PHYSANIM_BLENDER:-4.5}")"
cd "$here"
case "${1:-}" in
  cloth) shift; exec "$venv/bin/python" bench/cloth.py "$@" ;;
  cloth-self) shift; exec "$venv/bin/python" bench/cloth_self.py "$@" ;;
  broadphase) shift; exec "$venv/bin/python" bench/broadphase.py "$@" ;;
  collision) shift; exec "$venv/bin/python" bench/collision.py "$@" ;;
  rigid) shift; exec "$venv/bin/python" bench/rigid.py "$@" ;;
  chain) shift; exec "$venv/bin/python" bench/chain.py "$@" ;;
  interactions) shift; exec "$venv/bin/python" bench/interactions.py "$@" ;;
  sph) shift; exec "$venv/bin/python" bench/particle_pairs.py "$@" ;;
  heap) shift; exec "$venv/bin/python" bench/heap.py "$@" ;;
  particles) shift; exec "$venv/bin/python" bench/particles.py "$@" ;;
  *) exec "$venv/bin/python" bench/particles.py "$@" ;;
esac
