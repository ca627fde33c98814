"""The benchmarks' docs writer (benchmarks/_record.py): a re-run replaces the table and keeps the notes below the mark."""

import json

from _benchmarks import load_benchmark_module


def test_a_rerun_replaces_the_table_and_keeps_the_notes(tmp_path):
    rec = load_benchmark_module("_record")
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
