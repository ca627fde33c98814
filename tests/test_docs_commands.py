"""Every shell command documented in README.md, docs/*.md and examples/*/README.md works as written.

The fenced ``bash`` blocks are read from the files themselves; each command (each part of an
``&&`` chain, so that the Quick start's own analysis runs too) runs, unchanged,
in a temporary folder set up as the README's Quick start leaves a clone: ``.venv`` (here a
link to the environment running the tests, with this tree first on ``PYTHONPATH``) and the
repository's ``examples/``. Commands that set up the environment, need a cluster, a server,
Blender or several minutes are listed in :data:`NOT_RUN` with the reason; every other one runs.
A command documented with an error (``glassdist: error`` in its block or in the output block
after it) must exit 2; every other one 0 or 3 (a specification FAIL).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DOC_FILES = [REPO / "README.md", *sorted(p for p in (REPO / "docs").rglob("*.md") if "_build" not in p.parts),
             *sorted((REPO / "examples").glob("*/README.md"))]

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
]

_SHELL = {"bash", "sh", "shell", "console"}


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


def test_documented_commands_found():
    """The extraction sees the documented commands, and every glassdist command names the environment's."""
    assert len(COMMANDS) > 20
    bare = [(where, c) for where, c, _ in COMMANDS if re.match(r"\s*(glassdist|python3? -m glassdist)\b", c)]
    assert bare == []  # 'glassdist: command not found' after the Quick start
    runnable = [c for _, c, _ in COMMANDS if _not_run(c) is None and "glassdist" in c]
    assert len(runnable) >= 6


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
    done = subprocess.run(["bash", "-c", command], cwd=root, env=env, capture_output=True, text=True, timeout=180)
    out = done.stdout + done.stderr
    assert "command not found" not in out and "Traceback" not in out, out
    assert done.returncode in expect, f"{where}: exit {done.returncode}\n{out}"
