#!/usr/bin/env bash
# Create (when missing) and print the path of a venv holding the pinned `bpy` wheel (or, for
# "lint", the pinned ruff).
# Usage: tools/venv.sh [4.5|4.2|5.0|lint|farm]   (default 4.5, the primary LTS; "farm" holds the
# Open Job Description tools the farm tests validate and run the job templates with)
# Venvs live under $PHYSANIM_VENVS (default ~/.cache/physanim/venvs) so CI and repeated runs reuse them.
set -euo pipefail
ver="${1:-4.5}"
case "$ver" in
  4.2) pins="bpy==4.2.23 numpy==1.26.4" ;;
  4.5) pins="bpy==4.5.4" ;;
  5.0) pins="bpy==5.0.1" ;;
  lint) pins="ruff==0.17.6" ;;
  farm) pins="openjd-cli==0.8.0 openjd-model==0.13.0 openjd-sessions==0.13.0" ;;
  *) echo "tools/venv.sh: unknown Blender version '$ver' (use 4.2, 4.5, 5.0, lint or farm)" >&2; exit 2 ;;
esac
root="${PHYSANIM_VENVS:-$HOME/.cache/physanim/venvs}"
case "$ver" in
  lint|farm) venv="$root/$ver"; want="$pins" ;;
  *) venv="$root/bpy-$ver"; want="$pins pytest==8.3.3 pytest-xdist==3.8.0" ;;
esac
stamp="$venv/.physanim-ready"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  py="${PYTHON:-python3.11}"
  command -v "$py" >/dev/null 2>&1 || py=python3
  "$py" -c 'import sys; assert sys.version_info[:2] == (3, 11), "bpy wheels need Python 3.11, got %s" % sys.version' >&2
  rm -rf "$venv"; mkdir -p "$root"
  "$py" -m venv "$venv" >&2
  "$venv/bin/python" -m pip install --quiet $want >&2
  echo "$want" > "$stamp"
fi
if [ "$ver" = lint ] || [ "$ver" = farm ]; then echo "$venv"; exit 0; fi
# The bpy wheel links against X11/GL/EGL system libraries; a bare machine may lack them.
if ! "$venv/bin/python" -c "import bpy" >/dev/null 2>&1; then
  libs="libx11-6 libxrender1 libxi6 libxxf86vm1 libxfixes3 libxkbcommon0 libsm6 libice6 libgl1
        libgomp1 libegl1 libegl-mesa0 libgl1-mesa-dri libxext6 libxcursor1 libxinerama1 libxrandr2"
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "tools/venv.sh: installing the system libraries bpy needs" >&2
    apt-get update -qq >&2 && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $libs >&2
  fi
  if ! err="$("$venv/bin/python" -c "import bpy" 2>&1)"; then
    echo "tools/venv.sh: 'import bpy' fails in $venv:" >&2
    echo "$err" | tail -n 3 >&2
    echo "install these system packages (Debian names): $libs" >&2
    exit 1
  fi
fi
echo "$venv"
