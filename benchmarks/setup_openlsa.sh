#!/usr/bin/env bash
# Optional peer for benchmarks/bench_analyze.py: OpenLSA in its own environment (it pins numpy < 2).
set -euo pipefail
venv="${GLASSDIST_OPENLSA_VENV:-$HOME/.cache/glassdist/openlsa-venv}"
python3 -m venv "$venv"
"$venv/bin/pip" install -q openlsa
echo "OpenLSA ready: $venv/bin/python"
