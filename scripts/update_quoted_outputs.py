"""Run the commands whose output the documentation quotes, and compare or rewrite the quotes.

The convention (every ``.md`` file of the repository, wherever it lies): a fenced block whose
language is ``console`` is a terminal session. A line starting with ``$ `` is a command (a
trailing ``\\`` continues it on the next line); the lines after it, up to the next ``$ `` line
or the end of the block, are exactly what it prints, standard output and standard error
together, as on a terminal. A line that is just ``...`` stands for any number of printed lines
left out (use it for lines whose numbers vary from run to run, such as timings: they are never
quoted). ``$ echo "exit status $?"`` quotes the exit status of the command before it.
Everything else (prose, ``bash`` blocks) is not compared::

    ```console
    $ .venv/bin/glassdist analyze examples/images/factory_pane.png ... --out out/factory
    comparative method: measured ...
    results written to out/factory
    $ echo "exit status $?"
    exit status 0
    ```

The commands of one block run in order in one shell, in a folder laid out as the README's
Quick start leaves a clone (``.venv``, ``examples/``), from the documented working folder (the
repository root); the parts of an ``&&`` chain that set up the environment (``python3 -m venv``,
``pip install``) are left out. ``tests/test_docs_commands.py`` runs every block and fails where
a quote differs from what the command prints; this script rewrites the quotes from the commands::

    PYTHONPATH=src .venv/bin/python scripts/update_quoted_outputs.py            # rewrite every quote
    PYTHONPATH=src .venv/bin/python scripts/update_quoted_outputs.py --check    # compare only (exit 1 if one differs)
    PYTHONPATH=src .venv/bin/python scripts/update_quoted_outputs.py README.md  # some files only

It must run from a virtual environment where glassdist is installed (``.venv`` of the clone).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: Folders never scanned for documentation.
SKIP_DIRS = {".git", ".venv", "node_modules", "build", "_build", "out", ".pytest_cache", ".ruff_cache"}
#: Parts of an ``&&`` chain that set up the environment: left out when a quoted command runs.
SETUP = re.compile(r"^\s*(python3 -m venv|\S*pip install)\b")
ELLIPSIS = "..."
_MARK = "@@glassdist-quoted-output {}@@"


@dataclasses.dataclass
class Step:
    """One ``$ `` command of a console block and the lines quoted as its output."""

    command: str
    quoted: list[str]
    line: int  # 1-based line number of the ``$`` line in its file


@dataclasses.dataclass
class Block:
    """A ``console`` block: its file, the line range of its body (0-based, end excluded), its steps."""

    path: Path
    start: int
    end: int
    steps: list[Step]

    @property
    def where(self) -> str:
        return f"{self.path.relative_to(REPO)}:{self.start}"


def markdown_files(root: Path = REPO) -> list[Path]:
    """Every ``.md`` file under ``root``, outside :data:`SKIP_DIRS` (sorted)."""
    found = []
    for folder, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if d not in SKIP_DIRS and not d.startswith("."))
        found += [Path(folder) / f for f in files if f.endswith(".md")]
    return sorted(found)


def console_blocks(path: Path) -> list[Block]:
    """The ``console`` blocks of ``path``."""
    lines = path.read_text(encoding="utf-8").splitlines()
    blocks, i = [], 0
    while i < len(lines):
        if lines[i].strip() == "```console":
            start = i + 1
            end = next((j for j in range(start, len(lines)) if lines[j].startswith("```")), len(lines))
            blocks.append(Block(path, start, end, _steps(lines[start:end], start)))
            i = end + 1
        else:
            i += 1
    return blocks


def _steps(body: list[str], offset: int) -> list[Step]:
    steps: list[Step] = []
    i = 0
    while i < len(body):
        line = body[i]
        if line.startswith("$ "):
            number, command = offset + i + 1, line[2:]
            while command.endswith("\\") and i + 1 < len(body):
                i += 1
                command = command[:-1] + " " + body[i].strip()
            steps.append(Step(command.strip(), [], number))
        elif steps:
            steps[-1].quoted.append(line.rstrip())
        i += 1
    for step in steps:
        while step.quoted and not step.quoted[-1]:
            step.quoted.pop()
    return steps


def runnable(command: str) -> str:
    """``command`` without the environment set-up parts of its ``&&`` chain."""
    parts = [p for p in command.split(" && ") if not SETUP.match(p)]
    return " && ".join(parts) or "true"


def clone_like(root: Path) -> dict[str, str]:
    """Lay ``root`` out as the Quick start leaves a clone; the environment the commands run with."""
    venv = Path(sys.prefix)
    if venv == Path(sys.base_prefix) or not (venv / "bin" / "glassdist").exists():
        raise RuntimeError("run from a virtual environment with glassdist installed (e.g. .venv/bin/python)")
    for name, target in ((".venv", venv), ("examples", REPO / "examples")):
        if not (root / name).exists():
            (root / name).symlink_to(target, target_is_directory=True)
    path = os.pathsep.join(filter(None, [str(REPO / "src"), os.environ.get("PYTHONPATH")]))
    # the runs' results history goes to the folder, never the user's
    return {**os.environ, "PYTHONPATH": path, "PYTHONUNBUFFERED": "1", "MPLBACKEND": "Agg",
            "COLUMNS": "200", "NO_COLOR": "1", "TERM": "dumb", "GLASSDIST_DB": str(root / "history.sqlite")}


def run_block(block: Block, root: Path, env: dict[str, str], timeout: float = 600) -> list[list[str]]:
    """Run the block's commands in order in one shell in ``root``; the lines each printed."""
    script = ["__quoted_status=0"]
    for k, step in enumerate(block.steps):
        script += [f"printf '%s\\n' '{_MARK.format(k)}'", "(exit $__quoted_status)",
                   f"{{ {runnable(step.command)}\n}} 2>&1", "__quoted_status=$?"]
    done = subprocess.run(["bash", "-c", "\n".join(script)], check=False, cwd=root, env=env, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True, timeout=timeout)
    outputs: list[list[str]] = []
    for line in done.stdout.split("\n"):
        if line.startswith("@@glassdist-quoted-output "):
            outputs.append([])
        elif outputs:
            outputs[-1].append(line.rstrip())
    for out in outputs:
        while out and not out[-1]:
            out.pop()
    return outputs


def matches(quoted: list[str], printed: list[str]) -> bool:
    """Whether ``printed`` is ``quoted``, a ``...`` line standing for any lines (none included)."""
    pattern = "".join(".*?" if q == ELLIPSIS else re.escape(q + "\n") for q in quoted)
    return re.fullmatch(pattern, "".join(p + "\n" for p in printed), flags=re.DOTALL) is not None


def requote(quoted: list[str], printed: list[str]) -> list[str]:
    """The new quote of ``printed``: its lines, with a ``...`` kept where ``quoted`` had one."""
    if ELLIPSIS not in quoted:
        return printed
    k = quoted.index(ELLIPSIS)
    after = len(quoted) - k - 1
    return printed[:k] + [ELLIPSIS] + (printed[len(printed) - after:] if after else [])


def differences(block: Block, printed: list[list[str]]) -> list[str]:
    """One message per step whose quote is not what it printed."""
    out = []
    if len(printed) != len(block.steps):
        return [f"{block.where}: {len(printed)} of {len(block.steps)} commands ran"]
    for step, lines in zip(block.steps, printed):
        if not matches(step.quoted, lines):
            out.append(f"{block.path.relative_to(REPO)}:{step.line}: `{step.command[:80]}` printed\n"
                       + "\n".join(lines) + "\n--- where the document quotes ---\n" + "\n".join(step.quoted))
    return out


def rewrite(path: Path, results: list[tuple[Block, list[list[str]]]]) -> bool:
    """Rewrite the quotes of ``path``'s blocks from what the commands printed; True if the file changed."""
    lines = path.read_text(encoding="utf-8").splitlines()
    old = list(lines)
    for block, printed in sorted(results, key=lambda r: -r[0].start):
        body = []
        for step, out in zip(block.steps, printed):
            body.append("$ " + step.command)
            body += requote(step.quoted, out)
        original = lines[block.start:block.end]
        if any(line.endswith("\\") for line in original if line.startswith("$ ")):
            body = _keep_continuations(original, block.steps, body)
        lines[block.start:block.end] = body
    if lines != old:
        path.write_text("\n".join(lines) + "\n", encoding="utf-8")
        return True
    return False


def _keep_continuations(original: list[str], steps: list[Step], body: list[str]) -> list[str]:
    """``body`` with each command written over the lines it had (its ``\\`` continuations kept)."""
    written: dict[str, list[str]] = {}
    i = 0
    for step in steps:
        while not original[i].startswith("$ "):
            i += 1
        j = i
        while original[j].endswith("\\"):
            j += 1
        written["$ " + step.command] = original[i:j + 1]
        i = j + 1
    out = []
    for line in body:
        out += written.get(line, [line]) if line.startswith("$ ") else [line]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="*", type=Path, help="Markdown files (default: every .md file of the repository)")
    ap.add_argument("--check", action="store_true", help="compare only; exit 1 where a quote differs")
    args = ap.parse_args(argv)
    files = [f.resolve() for f in args.files] or markdown_files()
    failed, changed, count = [], [], 0
    with tempfile.TemporaryDirectory() as tmp:
        env = clone_like(Path(tmp))
        for path in files:
            results = []
            for block in console_blocks(path):
                printed = run_block(block, Path(tmp), env)
                count += 1
                failed += differences(block, printed)
                results.append((block, printed))
            if results and not args.check and rewrite(path, results):
                changed.append(str(path.relative_to(REPO)))
    if args.check:
        print("\n\n".join(failed) or f"{count} quoted blocks reproduce")
        return 1 if failed else 0
    print("\n".join(f"rewrote {c}" for c in changed) or f"{count} quoted blocks already reproduce")
    return 0


if __name__ == "__main__":
    sys.exit(main())
