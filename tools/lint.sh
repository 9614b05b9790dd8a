#!/usr/bin/env bash
# Lint the repository with the pinned ruff (rules in ruff.toml); sets up its own venv when missing.
# Usage: tools/lint.sh [ruff check args...]
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
pin="ruff==0.17.6"
root="${PHYSANIM_VENVS:-$HOME/.cache/physanim/venvs}"
venv="$root/lint"
stamp="$venv/.physanim-ready"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$pin" ]; then
  py="${PYTHON:-python3.11}"
  command -v "$py" >/dev/null 2>&1 || py=python3
  rm -rf "$venv"; mkdir -p "$root"
  "$py" -m venv "$venv" >&2
  "$venv/bin/python" -m pip install --quiet "$pin" >&2
  echo "$pin" > "$stamp"
fi
cd "$here"
exec "$venv/bin/ruff" check --no-cache "${@:-.}"
