"""Mutation testing of the core: do the tests notice when the code is changed a little?

Each mutant changes one operator or constant of one function of a core module (Block F
``analyzer/fourier.py`` and its F5 deformation ``analyzer/deform.py``, the unwrapping ``analyzer/unwrap.py``, Block I
``analyzer/homography.py`` and its lens model ``analyzer/lens.py``, Block A ``analyzer/metrics.py``, its bulk
channel ``analyzer/bulk.py`` and the uncertainty maps ``analyzer/uncertainty.py``, the acceptance checks
``acceptance/assess.py`` and ``acceptance/spec.py``). It is written into a scratch copy of
``src/`` and the module's targeted tests run against it (``PYTHONPATH``, first failure
stops the run). A mutant is *killed* when a test fails (or the run exceeds the time
limit), *survived* otherwise. The mutants are a seeded random sample of every possible
one (``--per-module``; all of them with ``--per-module 0``).

Operators: ``+`` <-> ``-``, ``*`` <-> ``/``, ``**`` -> ``*``, ``//`` -> ``/``, comparisons
(``<`` <-> ``<=``, ``>`` <-> ``>=``, ``==`` <-> ``!=``), ``and`` <-> ``or``, unary minus
and ``not`` removed, numeric constants (0 -> 1, 1 -> 2, other ints n -> n + 1, floats
x -> 1.5 x, 0.0 -> 1.0), ``True`` <-> ``False``. Docstrings, annotations, log and error
messages are not mutated.

Usage::

    python scripts/mutation.py [--per-module 25 | --total 200] [--seed 0] [--modules metrics,acceptance:10]
                               [--jobs 1] [--timeout-factor 3] [--out mutation.json] [--python PYTHON]
                               [--function NAME] [--tests TEST,...]

Writes a JSON record (every mutant: module, line, the changed source line, the outcome)
and prints the kill rate per module, each surviving mutant, and the overall kill rate with
its 95 % Wilson interval (the sample's binomial uncertainty). It need not run in CI:
a full sample takes about 40 minutes on two cores (docs/validation/testing.md).
"""

from __future__ import annotations

import argparse
import ast
import copy
import json
import os
import queue
import random
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

#: module (under src/glassdist) -> the tests that target it (fast: about 10-20 s each run)
MODULES = {
    "fourier": ("analyzer/fourier.py", ["tests/test_analyzer_fourier.py", "tests/test_accuracy_truth.py",
                                       "tests/test_adversarial_limits.py::test_a_grid_finer_than_3_px_is_refused"]),
    "deform": ("analyzer/deform.py", ["tests/test_analyzer_deform.py", "tests/test_accuracy_truth.py",
                                     "tests/test_analyzer_quality.py::test_every_label_has_its_cause",
                                     "tests/test_real_photos.py::test_waves_field_explains_the_photo_and_agrees_with_fcd"]),
    "unwrap": ("analyzer/unwrap.py", ["tests/test_analyzer_unwrap.py", "tests/test_accuracy_truth.py"]),
    "homography": ("analyzer/homography.py", ["tests/test_analyzer_homography.py", "tests/test_homography_refit.py",
                                             "tests/test_accuracy_truth.py", "tests/test_lens.py",
                                             "tests/test_real_photos.py::test_the_waves_photos_lens_is_applied_when_the_photo_is_inverted"]),
    "lens": ("analyzer/lens.py", ["tests/test_analyzer_homography.py", "tests/test_lens.py"]),
    "bulk": ("analyzer/bulk.py", ["tests/test_analyzer_bulk.py",
                                 "tests/test_lens.py::test_bulk_channel_of_the_pillowed_igu"]),
    "metrics": ("analyzer/metrics.py", ["tests/test_analyzer_metrics.py", "tests/test_streamed_statistics.py",
                                       "tests/test_accuracy_truth.py"]),
    "uncertainty": ("analyzer/uncertainty.py", [
        "tests/test_analyzer_quality.py::test_deformation_noise_gains_closed_form",
        "tests/test_analyzer_quality.py::test_deformation_channel_gain_against_a_radial_integral",
        "tests/test_analyzer_quality.py::test_deformation_noise_gains_against_a_double_integral",
        "tests/test_analyzer_quality.py::test_channel_uncertainty_of_an_oblique_shear_against_the_strain_covariance",
        "tests/test_analyzer_quality.py::test_uncertainty_matches_monte_carlo",
        "tests/test_analyzer_quality.py::test_uncertainty_scales_with_noise_and_fields_are_registered",
        "tests/test_analyzer_quality.py::test_uncertainty_matches_the_scatter_of_single_captures_of_a_strong_wave"]),
    "acceptance": ("acceptance/assess.py", ["tests/test_acceptance.py"]),
    "spec": ("acceptance/spec.py", ["tests/test_spec.py", "tests/test_acceptance.py"]),
}

_SWAP = {ast.Add: ast.Sub, ast.Sub: ast.Add, ast.Mult: ast.Div, ast.Div: ast.Mult, ast.Pow: ast.Mult,
         ast.FloorDiv: ast.Div, ast.Lt: ast.LtE, ast.LtE: ast.Lt, ast.Gt: ast.GtE, ast.GtE: ast.Gt,
         ast.Eq: ast.NotEq, ast.NotEq: ast.Eq, ast.And: ast.Or, ast.Or: ast.And}
_QUIET_CALLS = {"warn", "warning", "debug", "info", "error", "append", "InputError", "AnalysisError", "ValueError",
                "TypeError", "RuntimeError"}


def _skipped_nodes(tree: ast.AST) -> set[int]:
    """ids of nodes never mutated: docstrings, annotations, messages (f-strings and what they format)."""
    skip = set()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
            skip.update(id(n) for n in ast.walk(body[0]))
        for ann in (getattr(node, "annotation", None), getattr(node, "returns", None)):
            if ann is not None:
                skip.update(id(n) for n in ast.walk(ann))
        if isinstance(node, ast.JoinedStr):
            skip.update(id(n) for n in ast.walk(node))
        if isinstance(node, ast.Call):
            name = getattr(node.func, "attr", getattr(node.func, "id", ""))
            if name in _QUIET_CALLS:
                skip.update(id(n) for a in node.args for n in ast.walk(a))
        if isinstance(node, ast.Assign) and any(getattr(t, "id", "") == "__all__" for t in node.targets):
            skip.update(id(n) for n in ast.walk(node))
    return skip


def _points(tree: ast.AST) -> list[tuple[int, str]]:
    """Every mutation point: (index of the node in ast.walk order, kind)."""
    skip = _skipped_nodes(tree)
    out = []
    inside_function = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            inside_function.update(id(n) for stmt in node.body for n in ast.walk(stmt))
    for i, node in enumerate(ast.walk(tree)):
        if id(node) in skip or id(node) not in inside_function:
            continue
        if isinstance(node, (ast.BinOp, ast.AugAssign)) and type(node.op) in _SWAP:
            out.append((i, "binop"))
        elif isinstance(node, ast.Compare) and type(node.ops[0]) in _SWAP:
            out.append((i, "compare"))
        elif isinstance(node, ast.BoolOp):
            out.append((i, "boolop"))
        elif isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.Not)):
            out.append((i, "unary"))
        elif isinstance(node, ast.Constant) and type(node.value) in (int, float, bool):
            out.append((i, "constant"))
    return out


def _mutate(tree: ast.AST, index: int) -> tuple[ast.AST, int]:
    """A copy of ``tree`` with the ``index``-th node (ast.walk order) mutated; and its line."""
    new = copy.deepcopy(tree)
    node = list(ast.walk(new))[index]
    line = node.lineno
    if isinstance(node, (ast.BinOp, ast.AugAssign)):
        node.op = _SWAP[type(node.op)]()
    elif isinstance(node, ast.Compare):
        node.ops[0] = _SWAP[type(node.ops[0])]()
    elif isinstance(node, ast.BoolOp):
        node.op = _SWAP[type(node.op)]()
    elif isinstance(node, ast.UnaryOp):
        parent = next(p for p in ast.walk(new) for f, v in ast.iter_fields(p)
                      if v is node or (isinstance(v, list) and any(x is node for x in v)))
        for f, v in ast.iter_fields(parent):
            if v is node:
                setattr(parent, f, node.operand)
            elif isinstance(v, list):
                v[:] = [node.operand if x is node else x for x in v]
    elif isinstance(node, ast.Constant):
        v = node.value
        if isinstance(v, bool):
            node.value = not v
        elif isinstance(v, int):
            node.value = v + 1
        else:
            node.value = 1.0 if v == 0 else v * 1.5
    return ast.fix_missing_locations(new), line


def _run_tests(python: str, src: Path, tests: list[str], timeout_s: float) -> tuple[str, float]:
    env = dict(os.environ, PYTHONPATH=str(src), PYTHONDONTWRITEBYTECODE="1", MPLBACKEND="Agg")
    t0 = time.monotonic()
    try:
        r = subprocess.run([python, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", *tests], cwd=REPO, env=env,
                           capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return "killed (timeout)", time.monotonic() - t0
    dt = time.monotonic() - t0
    if r.returncode == 0:
        return "survived", dt
    if r.returncode == 1:
        return "killed", dt
    return f"killed (pytest exit {r.returncode})", dt  # e.g. an import error of the mutant


def _stratified(counts: dict[str, int], total: int) -> dict[str, int]:
    """``total`` mutants shared among the modules in proportion to their mutants (largest remainder, >= 1 each)."""
    n = sum(counts.values())
    share = {k: total * c / n for k, c in counts.items()}
    out = {k: max(1, int(v)) for k, v in share.items()}
    for k in sorted(share, key=lambda k: share[k] - int(share[k]), reverse=True):
        if sum(out.values()) >= total:
            break
        out[k] += 1
    return {k: min(v, counts[k]) for k, v in out.items()}


def wilson_interval(k: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """The Wilson score interval (95 % by default) of a binomial proportion ``k / n``."""
    if n == 0:
        return 0.0, 1.0
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * ((p * (1 - p) / n + z * z / (4 * n * n)) ** 0.5) / (1 + z * z / n)
    return centre - half, centre + half


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-module", type=int, default=25, help="mutants sampled per module (0: all)")
    ap.add_argument("--total", type=int, default=None,
                    help="a stratified sample: this many mutants in all, shared among the modules in proportion "
                         "to their number of mutants (overrides --per-module)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--modules", default=",".join(MODULES),
                    help="comma-separated subset of " + ", ".join(MODULES) + "; NAME:N samples N mutants of that one")
    ap.add_argument("--out", type=Path, default=Path("mutation.json"))
    ap.add_argument("--python", default=sys.executable)
    ap.add_argument("--jobs", type=int, default=1, help="mutants tested at once (each in its own scratch copy)")
    ap.add_argument("--timeout-factor", type=float, default=3.0,
                    help="a mutant whose tests run longer than this many times the unchanged run is killed (timeout)")
    ap.add_argument("--function", default=None,
                    help="only the mutants inside the function (or method) of this name, in each module")
    ap.add_argument("--tests", default=None,
                    help="comma-separated tests to run instead of the modules' targeted tests (e.g. those of --function)")
    ap.add_argument("--stop-after-min", type=float, default=None,
                    help="start no mutant after this many minutes (the record keeps those tested)")
    args = ap.parse_args(argv)
    stop_at = time.monotonic() + 60 * args.stop_after_min if args.stop_after_min else float("inf")
    rng = random.Random(args.seed)
    record = {"seed": args.seed, "per_module": args.per_module, "total": args.total, "function": args.function,
              "tests": args.tests, "modules": {}}
    items = [item.partition(":") for item in args.modules.split(",")]
    trees = {name: ast.parse((REPO / "src" / "glassdist" / MODULES[name][0]).read_text()) for name, _, _ in items}
    targeted = {name: args.tests.split(",") if args.tests else MODULES[name][1] for name in trees}

    def points_of(name):
        points = _points(trees[name])
        if args.function is None:
            return points
        spans = [(n.lineno, n.end_lineno) for n in ast.walk(trees[name])
                 if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.name == args.function]
        if not spans:
            raise SystemExit(f"{name}: no function named {args.function!r}")
        nodes = list(ast.walk(trees[name]))
        return [(i, kind) for i, kind in points if any(a <= nodes[i].lineno <= b for a, b in spans)]

    counts = {name: len(points_of(name)) for name in trees}
    if args.total is not None:
        sizes = _stratified(counts, args.total)
    else:
        sizes = {name: int(count) if count else args.per_module for name, _, count in items}
    with tempfile.TemporaryDirectory(prefix="glassdist-mutation-") as tmp:
        # the experiments find their scenes beside src/ (examples/, docs/): the copies see the repository's
        for folder in ("examples", "docs"):
            (Path(tmp) / folder).symlink_to(REPO / folder, target_is_directory=True)
        copies = queue.Queue()
        for j in range(max(1, args.jobs)):
            src = Path(tmp) / f"src{j}"
            shutil.copytree(REPO / "src", src, ignore=shutil.ignore_patterns("__pycache__"))
            copies.put(src)
        names = [name for name, _, _ in items]
        originals = {name: (REPO / "src" / "glassdist" / MODULES[name][0]).read_text() for name in names}

        def baseline(name):
            src = copies.get()
            try:
                return _run_tests(args.python, src, targeted[name], 1200)
            finally:
                copies.put(src)

        with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
            base = dict(zip(names, pool.map(baseline, names)))
        chosen = []
        for name in names:
            if base[name][0] != "survived":
                raise SystemExit(f"{name}: the targeted tests fail on the unchanged code ({base[name][0]})")
            points = points_of(name)
            picked = sorted(rng.sample(points, min(len(points), sizes[name])) if sizes[name] else points)
            chosen += [(name, index, kind) for index, kind in picked]
            record["modules"][name] = []
            print(f"## {name}: {len(picked)} of {len(points)} mutants, tests {base[name][1]:.0f} s unchanged", flush=True)
        # all modules' mutants in one shuffled queue: a run stopped early has tested a random part of the sample
        rng.shuffle(chosen)
        lock = threading.Lock()

        def one(point):
            name, index, kind = point
            if time.monotonic() > stop_at:
                return None
            rel, tests = MODULES[name][0], targeted[name]
            tree, original = trees[name], originals[name]
            mutant, line = _mutate(tree, index)
            src = copies.get()
            path = src / "glassdist" / rel
            try:
                path.write_text(ast.unparse(mutant))
                outcome, dt = _run_tests(args.python, src, tests, max(60.0, args.timeout_factor * base[name][1]))
            finally:
                path.write_text(original)
                copies.put(src)
            source = original.splitlines()[line - 1].strip()
            print(f"  {outcome:<22} {rel}:{line} [{kind}] {source[:90]}", flush=True)
            result = {"line": line, "kind": kind, "source": source, "outcome": outcome, "seconds": round(dt, 1),
                      "mutant_context": _changed(ast.unparse(tree), ast.unparse(mutant).splitlines())}
            with lock:  # the record so far, written after each mutant (a stopped run keeps what it did)
                record["modules"][name].append(result)
                args.out.write_text(json.dumps(record, indent=1))
            return result

        with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
            list(pool.map(one, chosen))
        for name in names:
            results = record["modules"][name]
            killed = sum(r["outcome"].startswith("killed") for r in results)
            print(f"   {name}: {killed} of {len(results)} killed", flush=True)
    args.out.write_text(json.dumps(record, indent=1))
    total = sum(len(v) for v in record["modules"].values())
    killed = sum(r["outcome"].startswith("killed") for v in record["modules"].values() for r in v)
    lo, hi = wilson_interval(killed, total)
    print(f"killed {killed} of {total} ({100 * killed / max(total, 1):.1f} %, 95 % interval "
          f"{100 * lo:.1f}-{100 * hi:.1f} %)")
    return 0


def _changed(before: str, after: list[str]) -> str:
    """The first line of the unparsed module that the mutation changed (what the mutant reads)."""
    for a, b in zip(before.splitlines(), after):
        if a != b:
            return b.strip()
    return ""


if __name__ == "__main__":
    sys.exit(main())
