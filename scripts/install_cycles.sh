#!/usr/bin/env bash
# Install the Blender Cycles engine for `glassdist render --engine cycles`.
#
# Creates a separate virtual environment holding Blender's Python module
# (bpy 5.0.1: 374 MB download, about 1 GB installed, Python 3.11 only). It is
# kept apart from glassdist's environment because bpy pins NumPy 1.26.
#
#   bash scripts/install_cycles.sh             # -> ~/.cache/glassdist/cycles-venv
#   PYTHON=/opt/py311/bin/python3 bash scripts/install_cycles.sh
#
# Location: $GLASSDIST_CACHE_DIR/cycles-venv, else
# $XDG_CACHE_HOME/glassdist/cycles-venv, else ~/.cache/glassdist/cycles-venv
# (the same rule glassdist uses to find it). To use an interpreter that already
# has bpy instead, set GLASSDIST_CYCLES_PYTHON=/path/to/python and skip this.
set -euo pipefail

BPY="bpy==5.0.1"
cache="${GLASSDIST_CACHE_DIR:-${XDG_CACHE_HOME:-$HOME/.cache}/glassdist}"
env_dir="$cache/cycles-venv"

python="${PYTHON:-}"
if [[ -z "$python" ]]; then
    for candidate in python3.11 python3; do
        if command -v "$candidate" >/dev/null 2>&1 &&
           "$candidate" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
            python="$candidate"
            break
        fi
    done
fi
if [[ -z "$python" ]]; then
    echo "error: $BPY needs Python 3.11; install it or set PYTHON=/path/to/python3.11" >&2
    exit 2
fi

if [[ -x "$env_dir/bin/python" ]] && "$env_dir/bin/python" -c "import bpy" >/dev/null 2>&1; then
    echo "Cycles already installed: $env_dir/bin/python"
    exit 0
fi

rm -rf "$env_dir"
mkdir -p "$(dirname "$env_dir")"
echo "creating $env_dir with $("$python" --version) and $BPY (374 MB download)"
"$python" -m venv "$env_dir"
if ! "$env_dir/bin/python" -m pip install --disable-pip-version-check "$BPY"; then
    rm -rf "$env_dir"
    echo "error: pip could not install $BPY; check the network access to PyPI" >&2
    exit 1
fi
version=$("$env_dir/bin/python" -c "import bpy; print(bpy.app.version_string)")
echo "Cycles ready: $env_dir/bin/python (Blender $version)"
