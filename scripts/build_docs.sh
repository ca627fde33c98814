#!/usr/bin/env bash
# The documentation site, strict: warnings are errors (-W, all of them reported: --keep-going),
# every cross-reference must resolve (-n, nitpicky), the gallery is executed. Installs nothing:
# run it after `pip install -e ".[docs]"`. Internal links only (the build runs offline).
# Usage: bash scripts/build_docs.sh [PYTHON]   (default: .venv/bin/python if present, else python3)
set -euo pipefail
cd "$(dirname "$0")/.."
py=${1:-$( [ -x .venv/bin/python ] && echo .venv/bin/python || echo python3 )}
export MPLBACKEND=Agg
rm -rf docs/_build/html docs/_build/doctrees docs/gallery docs/_generated
exec "$py" -m sphinx -W --keep-going -n -b html -d docs/_build/doctrees docs docs/_build/html
