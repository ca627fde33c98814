"""The output of a benchmark that docs/ shows: its table, and its record beside it."""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path

#: The line after which a table's markdown holds notes written by hand; a re-run keeps them.
NOTES_MARK = "<!-- notes: written by hand below this line; the benchmark keeps them when it rewrites the table above -->"


def write_record(out: Path, script: str, argv, text: str, record: dict) -> None:
    """``out`` (markdown: the command that made it in a comment, then ``text``) and ``out`` as ``.json``.

    ``script``: the benchmark's file name; ``argv``: its arguments (``None``: the process's own).
    The JSON holds ``command`` and the items of ``record``. Whatever follows :data:`NOTES_MARK`
    in an existing ``out`` stays, after the new table.
    """
    cmd = (f"python benchmarks/{script} " + shlex.join(argv if argv is not None else sys.argv[1:])).strip()
    notes = ""
    if out.exists():
        old = out.read_text()
        if NOTES_MARK in old:
            notes = "\n" + NOTES_MARK + old.split(NOTES_MARK, 1)[1]
    out.write_text(f"<!-- {cmd} -->\n{text}\n{notes}")
    out.with_suffix(".json").write_text(json.dumps({"command": cmd, **record}, indent=1))
