#!/usr/bin/env bash
# Lint the repository with the pinned ruff (rules in ruff.toml); sets up its own venv when missing.
# Usage: tools/lint.sh [ruff check args...]
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$("$here/tools/venv.sh" lint)"
cd "$here"
exec "$venv/bin/ruff" check --no-cache "${@:-.}"
