"""The benchmarks' docs writer (benchmarks/_record.py): a re-run replaces the table and keeps the notes below the mark."""

import importlib.util
import json
from pathlib import Path


def _record():
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "_record.py"
    spec = importlib.util.spec_from_file_location("_record_under_test", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_a_rerun_replaces_the_table_and_keeps_the_notes(tmp_path):
    rec = _record()
    out = tmp_path / "table.md"
    rec.write_record(out, "bench_x.py", ["--out", "docs/table.md"], "| a |\n|---|\n| 1 |", {"value": 1})
    assert "| 1 |" in out.read_text() and rec.NOTES_MARK not in out.read_text()
    out.write_text(out.read_text() + "\n" + rec.NOTES_MARK + "\nWhy the figure is 1.\n")
    rec.write_record(out, "bench_x.py", ["--out", "docs/table.md"], "| a |\n|---|\n| 2 |", {"value": 2})
    text = out.read_text()
    assert text.startswith("<!-- python benchmarks/bench_x.py --out docs/table.md -->\n| a |")
    assert "| 2 |" in text and "| 1 |" not in text
    assert text.endswith(rec.NOTES_MARK + "\nWhy the figure is 1.\n") and text.count(rec.NOTES_MARK) == 1
    assert json.loads(out.with_suffix(".json").read_text()) == {"command": "python benchmarks/bench_x.py --out docs/table.md",
                                                                "value": 2}
