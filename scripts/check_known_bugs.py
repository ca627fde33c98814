"""Introduce four plausible analyzer bugs, one at a time, into a scratch copy and show which tests catch each.

Each bug is applied to a copy of ``src/`` in a temporary folder; the tests whose truth is
independent of the analyzer (``tests/_truth.py`` and closed forms) then run against that
copy (``PYTHONPATH``), and the tests that fail are listed. Every bug must fail at least one
of them; the script exits 1 otherwise (or when a bug's source line is no longer found:
update its pattern here after a change to the code it targets).

Usage::

    python scripts/check_known_bugs.py [--python PYTHON]

The bugs (docs/validation/testing.md):

1. the strain turned into the camera frame the wrong way (``R @ eps @ R.T``);
2. the A2 detrend fitted with degree N - 1;
3. the displacement 1.5 % too large;
4. the reporting smoothing 25 % wider than asked.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

#: name -> [(file under src/glassdist, exact text, replacement)]
BUGS = {
    "strain rotated the wrong way (R @ eps @ R.T)": [
        ("analyzer/metrics.py", "eps = R.T @ eps @ R", "eps = R @ eps @ R.T"),
    ],
    "A2 detrend with degree N - 1": [
        ("analyzer/metrics.py", "det = polynomial_detrend(displacement_mm, labels, detrend_degree, step_px)",
         "det = polynomial_detrend(displacement_mm, labels, max(detrend_degree - 1, 0), step_px)"),
    ],
    "displacement 1.5 % too large": [
        ("analyzer/components.py", "return Components(ag.phases * (p_c / (2 * np.pi)), J,",
         "return Components(ag.phases * (1.015 * p_c / (2 * np.pi)), J,"),
        ("analyzer/components.py", "return Components((proj_px @ np.linalg.inv(M)) * mm_per_px, None, None)",
         "return Components((proj_px @ np.linalg.inv(M)) * (1.015 * mm_per_px), None, None)"),
    ],
    "reporting smoothing 25 % wider": [
        ("analyzer/metrics.py", "outs = _smoothed_components(det, labels, sigma_mm / mm_per_px,",
         "outs = _smoothed_components(det, labels, 1.25 * sigma_mm / mm_per_px,"),
    ],
}

#: the tests whose truth is independent of the analyzer's evaluation stack
TESTS = [
    "tests/test_accuracy_truth.py",
    "tests/test_analyzer_pipeline.py::test_round_trip_against_truth",
    "tests/test_analyzer_pipeline.py::test_noisy_capture_within_five_percent",
]


def _apply(src: Path, patches) -> None:
    for rel, old, new in patches:
        path = src / "glassdist" / rel
        text = path.read_text()
        if text.count(old) != 1:
            raise SystemExit(f"{rel}: the line to change was not found exactly once: {old!r}; update BUGS in {__file__}")
        path.write_text(text.replace(old, new))


def _failed(output: str) -> list[str]:
    return sorted(set(re.findall(r"^FAILED (\S+)", output, flags=re.M)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--python", default=sys.executable, help="interpreter with glassdist's test dependencies")
    args = ap.parse_args(argv)
    missed = []
    for name, patches in BUGS.items():
        with tempfile.TemporaryDirectory(prefix="glassdist-bug-") as tmp:
            src = Path(tmp) / "src"
            shutil.copytree(REPO / "src", src, ignore=shutil.ignore_patterns("__pycache__"))
            _apply(src, patches)
            env = dict(os.environ, PYTHONPATH=str(src), PYTHONDONTWRITEBYTECODE="1")
            where = subprocess.run([args.python, "-c", "import glassdist; print(glassdist.__file__)"], env=env,
                                   capture_output=True, text=True, check=True).stdout.strip()
            if not where.startswith(str(src)):
                raise SystemExit(f"the scratch copy is not the one imported ({where})")
            run = subprocess.run([args.python, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-rf", *TESTS],
                                 cwd=REPO, env=env, capture_output=True, text=True)
        failed = _failed(run.stdout)
        tail = run.stdout.strip().splitlines()[-1] if run.stdout.strip() else run.stderr.strip()[-200:]
        print(f"## {name}\n{tail}")
        for f in failed:
            print(f"  caught by {f}")
        if not failed:
            print("  NOT CAUGHT")
            missed.append(name)
        print(flush=True)
    print("all four caught" if not missed else f"missed: {', '.join(missed)}")
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
