"""Every shell command documented in the repository's Markdown works as written, and every quoted output is what it prints.

Two kinds of fenced block are read from every ``.md`` file of the repository (wherever it lies,
``scripts/update_quoted_outputs.markdown_files``):

- ``bash`` (or ``sh``, ``shell``) blocks: each command (each part of an ``&&`` chain) runs,
  unchanged, in a temporary folder set up as the README's Quick start leaves a clone: ``.venv``
  (here a link to the environment running the tests, with this tree first on ``PYTHONPATH``) and
  the repository's ``examples/``. Commands that set up the environment, need a cluster, a
  server, Blender or several minutes are listed in :data:`NOT_RUN` with the reason; every other
  one runs. A command documented with an error (``glassdist: error`` in its block or in the
  output block after it) must exit 2; every other one 0 or 3 (a specification FAIL).
- ``console`` blocks: terminal sessions whose output is quoted (the convention is written in
  ``scripts/update_quoted_outputs.py``: ``$ `` lines are commands, the lines after them exactly
  what they print, ``...`` for lines left out). The commands of a block run in order in one shell
  in the same folder, and every quoted line is compared with what was printed: a change of
  behaviour fails here until the quote is re-run (``scripts/update_quoted_outputs.py``
  rewrites the quotes from the commands).

Output is quoted only in ``console`` blocks: a block of another kind that shows what glassdist
prints (a verdict, a summary line, an error) fails :func:`test_output_is_quoted_only_in_console_blocks`.
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _quotes_module():
    spec = importlib.util.spec_from_file_location("update_quoted_outputs", REPO / "scripts" / "update_quoted_outputs.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(spec.name, module)
    spec.loader.exec_module(module)
    return module


QUOTES = _quotes_module()
DOC_FILES = QUOTES.markdown_files(REPO)

#: Documented commands not run here: (regular expression searched in the command, why).
NOT_RUN = [
    (r"^python3 -m venv|pip install", "sets up the environment (the Quick start itself)"),
    (r"-m pytest", "the test suite itself"),
    (r"^\.venv/bin/dask |--scheduler|--workers", "needs a Dask cluster or starts one"),
    (r"cycles-setup|--engine cycles|install_cycles", "installs or runs Blender Cycles (minutes, network)"),
    (r"glassdist experiment ", "re-runs a paper experiment (minutes) and rewrites docs/"),
    (r"glassdist serve", "starts a server that runs until stopped"),
    (r"scripts/check_known_bugs|scripts/mutation", "re-runs parts of the test suite on mutated copies (minutes)"),
    (r"\bPANE\.png|\bMANIFEST\.csv|\bFOLDER\b|\bDIR\b|\[--|photos/", "a synopsis with placeholders, not a command"),
    (r"scripts/update_quoted_outputs", "re-runs every quoted block of the repository (minutes)"),
    (r"scripts/analyzer_flow", "profiles a run on the real photographs of ../shared/data/ (a record's recipe)"),
]

_SHELL = {"bash", "sh", "shell"}


def _blocks(path: Path):
    """``(language, first line number, text)`` of each fenced block of ``path``."""
    blocks, lang, start, body = [], None, 0, []
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if line.startswith("```"):
            if lang is None:
                lang, start, body = line[3:].strip(), number, []
            else:
                blocks.append((lang, start, "\n".join(body)))
                lang = None
        elif lang is not None:
            body.append(line)
    return blocks


def documented_commands():
    """``(file:line, command, expected exit statuses)`` of every command in a fenced shell block."""
    found = []
    for path in DOC_FILES:
        blocks = _blocks(path)
        for i, (lang, start, text) in enumerate(blocks):
            if lang not in _SHELL:
                continue
            following = blocks[i + 1][2] if i + 1 < len(blocks) and not blocks[i + 1][0] else ""
            expect = (2,) if "glassdist: error" in text + following else (0, 3)
            lines = re.sub(r"\\\n\s*", "", text).splitlines()
            for command in (part for line in lines for part in line.split(" && ")):
                if command.strip() and not command.lstrip().startswith("#"):
                    found.append((f"{path.relative_to(REPO)}:{start}", command, expect if "glassdist" in command else (0,)))
    return found


def _not_run(command: str):
    return next((why for pattern, why in NOT_RUN if re.search(pattern, command)), None)


COMMANDS = documented_commands()


QUOTED = [block for path in DOC_FILES for block in QUOTES.console_blocks(path)]
#: Output-like lines (what glassdist prints) that must sit in a ``console`` block.
_PRINTED = re.compile(r"^(glassdist: error|VERDICT: |(PASS|FAIL)  |results written to |report: |\[\d+/\d+\] |"
                      r"(comparative|direct) method: measured|exit status \d|\d+ panes: )")


def test_documented_commands_found():
    """The extraction sees the documented commands, and every glassdist command names the environment's."""
    steps = [(block.where, step.command) for block in QUOTED for step in block.steps]
    every = [(where, c) for where, c, _ in COMMANDS] + steps
    assert len(every) > 20
    bare = [(where, c) for where, c in every if re.match(r"\s*(glassdist|python3? -m glassdist)\b", c)]
    assert bare == []  # 'glassdist: command not found' after the Quick start
    runnable = [c for _, c in every if _not_run(c) is None and "glassdist" in c]
    assert len(runnable) >= 6


def test_the_readme_is_a_short_page():
    """The README is read in minutes (at most 200 lines); the manual is the documentation site."""
    text = (REPO / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 200
    assert "docs/getting-started/index.md" in text and "docs/reference/index.md" in text


def test_quoted_blocks_found():
    """The README's Quick start and the examples' sessions are read as quoted blocks, each command with its lines."""
    files = {str(block.path.relative_to(REPO)) for block in QUOTED}
    assert {"README.md", "examples/factory/README.md", "examples/insitu/README.md", "examples/batch/README.md",
            "examples/reflection/README.md"} <= files
    (quick,) = [b for b in QUOTED if b.path.name == "README.md" and b.path.parent == REPO]
    assert quick.steps[0].command.startswith("python3 -m venv .venv && .venv/bin/pip install -q -e . && "
                                             ".venv/bin/glassdist analyze examples/")
    assert QUOTES.runnable(quick.steps[0].command).startswith(".venv/bin/glassdist analyze ")
    assert all(step.quoted for block in QUOTED for step in block.steps if "echo" in step.command)


def test_the_quote_comparison_can_fail():
    """A changed, a missing or an extra line is a difference; ``...`` stands for any lines, none included."""
    printed = ["a 1", "b 2", "c 3"]
    assert QUOTES.matches(printed, printed)
    assert not QUOTES.matches(["a 1", "b 9", "c 3"], printed)
    assert not QUOTES.matches(["a 1", "b 2"], printed) and not QUOTES.matches([*printed, "d"], printed)
    assert QUOTES.matches(["a 1", "...", "c 3"], printed) and QUOTES.matches(["...", "a 1", "b 2", "c 3"], printed)
    assert not QUOTES.matches(["...", "b 2"], printed)
    assert QUOTES.requote(["x", "...", "y"], ["a", "b", "c", "d"]) == ["a", "...", "d"]


def test_output_is_quoted_only_in_console_blocks():
    """A block that shows what glassdist prints is a ``console`` block, so that its lines are compared."""
    found = []
    for path in DOC_FILES:
        rel = str(path.relative_to(REPO))
        for lang, start, text in _blocks(path):
            if lang != "console" and any(_PRINTED.match(line.lstrip("# ")) for line in text.splitlines()):
                found.append(f"{rel}:{start}")
    assert found == [], "quote these outputs in console blocks (scripts/update_quoted_outputs.py)"


@pytest.fixture(scope="module")
def after_quick_start(tmp_path_factory):
    """A folder as the Quick start leaves a clone: ``.venv`` and ``examples/``; the environment for commands."""
    venv = Path(sys.prefix)
    if venv == Path(sys.base_prefix) or not (venv / "bin" / "glassdist").exists():
        pytest.skip("the tests do not run from a virtual environment with glassdist installed")
    root = tmp_path_factory.mktemp("clone")
    (root / ".venv").symlink_to(venv, target_is_directory=True)
    (root / "examples").symlink_to(REPO / "examples", target_is_directory=True)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO / "src"), os.environ.get("PYTHONPATH")]))}
    return root, env


@pytest.mark.slow
@pytest.mark.parametrize("where, command, expect", COMMANDS, ids=[f"{w}:{c[:60]}" for w, c, _ in COMMANDS])
def test_documented_command_runs_as_written(where, command, expect, after_quick_start):
    why = _not_run(command)
    if why is not None:
        pytest.skip(f"not run here: {why}")
    root, env = after_quick_start
    done = subprocess.run(["bash", "-c", command], check=False, cwd=root, env=env, capture_output=True, text=True, timeout=180)
    out = done.stdout + done.stderr
    assert "command not found" not in out and "Traceback" not in out, out
    assert done.returncode in expect, f"{where}: exit {done.returncode}\n{out}"


@pytest.mark.slow
@pytest.mark.parametrize("block", QUOTED, ids=[b.where for b in QUOTED])
def test_quoted_output_is_what_the_commands_print(block, after_quick_start):
    """The block's commands, run in order in one shell, print exactly the quoted lines."""
    skipped = [why for step in block.steps if (why := _not_run(QUOTES.runnable(step.command)))]
    if skipped:
        pytest.skip(f"not run here: {skipped[0]}")
    root, _ = after_quick_start
    env = QUOTES.clone_like(root)
    printed = QUOTES.run_block(block, root, env)
    text = "\n".join(line for out in printed for line in out)
    assert "command not found" not in text and "Traceback" not in text, text
    problems = QUOTES.differences(block, printed)
    assert problems == [], "\n\n".join(problems) + "\n(re-run: scripts/update_quoted_outputs.py)"
