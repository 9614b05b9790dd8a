#!/usr/bin/env bash
# Create (when missing) and print the path of a venv holding the pinned `bpy` wheel.
# Usage: tools/venv.sh [4.5|4.2|5.0]   (default 4.5, the primary LTS)
# Venvs live under $PHYSANIM_VENVS (default ~/.cache/physanim/venvs) so CI and repeated runs reuse them.
set -euo pipefail
ver="${1:-4.5}"
case "$ver" in
  4.2) pins="bpy==4.2.23 numpy==1.26.4" ;;
  4.5) pins="bpy==4.5.4" ;;
  5.0) pins="bpy==5.0.1" ;;
  *) echo "tools/venv.sh: unknown Blender version '$ver' (use 4.2, 4.5 or 5.0)" >&2; exit 2 ;;
esac
root="${PHYSANIM_VENVS:-$HOME/.cache/physanim/venvs}"
venv="$root/bpy-$ver"
stamp="$venv/.physanim-ready"
want="$pins pytest==8.3.3"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  py="${PYTHON:-python3.11}"
  command -v "$py" >/dev/null 2>&1 || py=python3
  "$py" -c 'import sys; assert sys.version_info[:2] == (3, 11), "bpy wheels need Python 3.11, got %s" % sys.version' >&2
  rm -rf "$venv"; mkdir -p "$root"
  "$py" -m venv "$venv" >&2
  "$venv/bin/python" -m pip install --quiet $want >&2
  echo "$want" > "$stamp"
fi
echo "$venv"
