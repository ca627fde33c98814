"""Compare two folders of glassdist outputs file by file (a refactoring must leave them bit-identical).

Usage::

    python scripts/compare_runs.py BEFORE AFTER [--renamed OLD=NEW ...]

Every file under ``BEFORE`` must exist under ``AFTER`` (and the other way round):

* ``*.npz``: every array equal, bit for bit (NaN where NaN), same keys and dtypes;
* ``*.json``: equal values once the keys that legitimately change from run to run are
  dropped (times, durations, the version, the SHA-256 and size of the files that hold
  them) and the renamed keys (``--renamed a4.valid_percent=...``) are mapped;
* ``*.html``: equal once the generation time, the version and the ``summary.json`` digest
  are blanked;
* ``*.log``, ``*.stdout``, ``*.stderr``: equal once times and folder names are blanked;
* everything else (PNG figures, CSV tables, TIFF): byte-identical.

Exit status 0 when every file matches, 1 otherwise (one line per difference).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import numpy as np

#: keys whose values vary between two runs of the same code (dotted paths match anywhere)
VOLATILE = {"glassdist_version", "generated", "seconds", "started", "finished", "duration_s", "version",
            "created", "elapsed_s", "timestamp"}
#: text that varies between runs: times, durations, versions, temporary folders
_TEXT_VOLATILE = [
    (re.compile(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(\.\d+)?(\+00:00|Z)?"), "<time>"),
    (re.compile(r"\d{4}-\d\d-\d\d \d\d:\d\d(:\d\d)?( UTC)?"), "<time>"),
    (re.compile(r"\(\d+(\.\d+)? s\)"), "(<s>)"),
    (re.compile(r"\.tmp-[A-Za-z0-9._-]+-\d+-[0-9a-f]+"), ".tmp-<pane>"),
    (re.compile(r"\b\d+\.\d+ s\b"), "<s>"),
    (re.compile(r"glassdist \d+\.\d+[^\s<\"]*"), "glassdist <version>"),
]


def _volatile_outputs(name: str) -> bool:
    """Files whose bytes hold times (their size and SHA-256 in ``outputs`` then vary too)."""
    return name.endswith((".html", ".log", "pane.json"))


def _clean(obj, renamed: dict, path: str = ""):
    if isinstance(obj, dict):
        out = {}
        for k, v in obj.items():
            key = f"{path}.{k}" if path else k
            if k in VOLATILE or k.endswith("_utc"):
                continue
            if path.endswith("outputs") and isinstance(v, dict) and _volatile_outputs(k):
                v = {kk: vv for kk, vv in v.items() if kk not in ("sha256", "size")}
            newkey = renamed.get(key, key)
            if newkey is None:
                continue
            out[newkey.rsplit(".", 1)[-1]] = _clean(v, renamed, newkey)
        return out
    if isinstance(obj, list):
        return [_clean(v, renamed, path) for v in obj]
    return obj


def _text(s: str, roots) -> str:
    for root in roots:
        s = s.replace(str(root), "<root>")
    for pattern, repl in _TEXT_VOLATILE:
        s = pattern.sub(repl, s)
    return s


def compare_file(a: Path, b: Path, renamed: dict, roots) -> str | None:
    """None when ``a`` and ``b`` match under the rules of the module, else one line saying how they differ."""
    if a.suffix == ".npz":
        with np.load(a, allow_pickle=False) as za, np.load(b, allow_pickle=False) as zb:
            if sorted(za.files) != sorted(zb.files):
                return f"keys differ: {sorted(set(za.files) ^ set(zb.files))}"
            for k in za.files:
                x, y = za[k], zb[k]
                if x.dtype != y.dtype or x.shape != y.shape or x.tobytes() != y.tobytes():
                    return f"array '{k}' differs"
        return None
    if a.suffix == ".json":
        x = _clean(json.loads(a.read_text()), renamed)
        y = _clean(json.loads(b.read_text()), {})
        if x != y:
            return f"values differ: {_first_difference(x, y)}"
        return None
    if a.name == "index.csv":  # the batch index: every column but the pane's duration
        x, y = (_csv_rows(p, renamed if p is a else {}) for p in (a, b))
        return None if x == y else f"rows differ: {_first_line_difference(x, y)}"
    if a.suffix in (".html", ".log", ".stdout", ".stderr"):
        x, y = _text(a.read_text(errors="replace"), roots), _text(b.read_text(errors="replace"), roots)
        if a.suffix == ".html":  # the batch index's durations
            x, y = (re.sub(r"<td>\d+\.\d+</td>(?=<td><a href=\"panes/)", "<td>s</td>", t) for t in (x, y))
        return None if x == y else f"text differs: {_first_line_difference(x, y)}"
    return None if a.read_bytes() == b.read_bytes() else "bytes differ"


def _csv_rows(path: Path, renamed: dict) -> str:
    import csv

    rows = list(csv.DictReader(path.open(newline="")))
    return "\n".join(repr({renamed.get(k, k): v for k, v in r.items() if k != "seconds"}) for r in rows)


def _first_difference(x, y, path="") -> str:
    if isinstance(x, dict) and isinstance(y, dict):
        for k in sorted(set(x) | set(y)):
            if k not in x or k not in y:
                return f"{path}.{k} only in {'after' if k not in x else 'before'}"
            if x[k] != y[k]:
                return _first_difference(x[k], y[k], f"{path}.{k}")
    if isinstance(x, list) and isinstance(y, list) and len(x) == len(y):
        for i, (u, v) in enumerate(zip(x, y)):
            if u != v:
                return _first_difference(u, v, f"{path}[{i}]")
    return f"{path}: {str(x)[:80]} != {str(y)[:80]}"


def _first_line_difference(x: str, y: str) -> str:
    for i, (u, v) in enumerate(zip(x.splitlines(), y.splitlines())):
        if u != v:
            return f"line {i + 1}: {u[:100]!r} != {v[:100]!r}"
    return "different number of lines"


def compare(before: Path, after: Path, renamed: dict) -> list[str]:
    """One line per file that differs or is missing on either side."""
    files_a = {p.relative_to(before) for p in before.rglob("*") if p.is_file()}
    files_b = {p.relative_to(after) for p in after.rglob("*") if p.is_file()}
    problems = [f"only before: {p}" for p in sorted(files_a - files_b)]
    problems += [f"only after: {p}" for p in sorted(files_b - files_a)]
    for rel in sorted(files_a & files_b):
        why = compare_file(before / rel, after / rel, renamed, (before.resolve(), after.resolve()))
        if why:
            problems.append(f"{rel}: {why}")
    return problems


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("before", type=Path)
    p.add_argument("after", type=Path)
    p.add_argument("--renamed", nargs="*", default=[], metavar="OLD=NEW",
                   help="a summary key renamed (dotted path; NEW empty: removed)")
    args = p.parse_args(argv)
    renamed = dict(r.split("=", 1) for r in args.renamed)
    renamed = {k: (v or None) for k, v in renamed.items()}
    problems = compare(args.before, args.after, renamed)
    for line in problems:
        print(line)
    n = sum(1 for p in args.before.rglob("*") if p.is_file())
    print(f"{n} files compared, {len(problems)} differences")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
