"""The output of a benchmark that docs/ shows: its table, and its record beside it."""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path


def write_record(out: Path, script: str, argv, text: str, record: dict) -> None:
    """``out`` (markdown: the command that made it in a comment, then ``text``) and ``out`` as ``.json``.

    ``script``: the benchmark's file name; ``argv``: its arguments (``None``: the process's own).
    The JSON holds ``command`` and the items of ``record``.
    """
    cmd = (f"python benchmarks/{script} " + shlex.join(argv if argv is not None else sys.argv[1:])).strip()
    out.write_text(f"<!-- {cmd} -->\n{text}\n")
    out.with_suffix(".json").write_text(json.dumps({"command": cmd, **record}, indent=1))
