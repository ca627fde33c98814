#!/usr/bin/env bash
# Lint and type-check: ruff (pyflakes, pycodestyle, isort, pydocstyle for public names) on the whole tree and
# mypy (strict on the analyzer and the acceptance), as configured in pyproject.toml. Exit status non-zero on any
# finding.
#   scripts/lint.sh            src, tests, benchmarks and scripts (the scope CI holds clean)
#   scripts/lint.sh PATH...    ruff on those paths only (mypy's files stay those of pyproject.toml)
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python}
paths=("$@")
[ ${#paths[@]} -eq 0 ] && paths=(src tests benchmarks scripts)
status=0
"$PY" -m ruff check "${paths[@]}" || status=1
"$PY" -m mypy || status=1
# the lazily loaded public names, as IDEs and mypy see them, match what loads at run time
"$PY" scripts/lazy_stubs.py --check || status=1
exit $status
