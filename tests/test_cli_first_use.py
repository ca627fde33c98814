"""What a first-time user trips over on the command line: guessed options, the user's own files, odd --out values."""

import errno
import re
import subprocess
import sys

import pytest

from conftest import run_cli, write_lens_pair
from glassdist import cli

_cli = run_cli  # in this process (conftest.run_cli)


def _child(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "glassdist", *map(str, args)], capture_output=True, text=True, cwd=cwd)


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    return write_lens_pair(tmp_path_factory.mktemp("lens"))


def _analyze(pair, out, *extra):
    return ["analyze", pair / "pane.png", "--reference", pair / "reference.png", "--pitch-mm", 2, "--distance-m", 1,
            "--pattern", "lines", *extra, "--out", out]


def _parsers(parser):
    """The parser and every sub-command's parser, recursively."""
    yield parser
    for action in parser._actions:
        for sub in (getattr(action, "choices", None) or {}).values() if hasattr(action, "_name_parser_map") else ():
            yield from _parsers(sub)


def test_no_parser_takes_an_abbreviation():
    parsers = list(_parsers(cli.build_parser()))
    assert len(parsers) > 8
    assert [p.prog for p in parsers if p.allow_abbrev] == []


def test_an_abbreviated_option_exits_2_with_a_suggestion(pair, tmp_path):
    r = _cli("analyze", pair / "pane.png", "--pitch", 5, "--distance-m", 1, "--out", tmp_path / "o")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert re.search(r"unrecognized arguments: --pitch 5; did you mean --pitch-mm\?", r.stderr), r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "o").exists()


@pytest.mark.parametrize("argv", [
    ["analyze", "x.png", "--pitch-mm", "5", "--distance-m", "1.5", "--out", "o", "--distance-m", "0.5"],
    ["analyze", "x.png", "--pitch-mm=5", "--pitch-mm=5", "--distance-m", "1", "--out", "o"],  # even the same value
    ["batch", "m.csv", "--out", "o", "--out", "p"],
])
def test_an_option_given_twice_exits_2_naming_both_values(pair, tmp_path, argv):
    """argparse keeps the last of two values silently: a script that appends its own --distance-m to
    another's would measure with whichever came last."""
    r = _cli(*argv, cwd=tmp_path)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert re.search(r"argument --[a-z-]+: given twice \(\S+ and \S+\); give it once", r.stderr), r.stderr
    assert not any(tmp_path.iterdir())  # nothing written, nothing read
    ns = cli.build_parser().parse_args(["analyze", "x.png", "--report", "--report", "--out", "o"])
    assert ns.report is True  # a flag given twice is still the flag


@pytest.mark.parametrize("role", ["reference", "capture", "lens photo"])
def test_the_same_photo_twice_exits_2(pair, tmp_path, role):
    """The photo given again: as its own reference (it read 0 mD everywhere, exit 0, and passed any
    specification), as a second capture (the average claimed 1/sqrt(2) of a noise it still had) or as
    the Direct Method's lens photo (the glass taken for the lens). A copy under another name is the
    same photo: the pixels are compared, not the names."""
    import shutil

    copy = shutil.copy(pair / "pane.png", tmp_path / "copy.png")
    extra = {"reference": ["--reference", copy], "capture": [copy, "--reference", pair / "reference.png"],
             "lens photo": ["--lens-photo", copy]}[role]
    r = _cli("analyze", pair / "pane.png", *extra, "--pitch-mm", 2, "--distance-m", 1, "--out", tmp_path / "o")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "is the same photo as" in r.stderr and "identical pixels" in r.stderr
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("argv, suggestion", [
    (["analyze", "x.png", "--pitch-mm", "5", "--distnce-m", "1", "--out", "o"], "--distance-m"),
    (["analyze", "x.png", "--pitch-mm=5", "--distance-m", "1", "--refrence=r.png", "--out", "o"], "--reference"),
    (["validate", "s.yaml", "--method", "direct", "--ot", "o"], None),  # required --out missing is said first
    (["batch", "m.csv", "--out", "o", "--reprot"], "--report"),
])
def test_a_misspelt_option_gets_did_you_mean(capsys, argv, suggestion):
    with pytest.raises(SystemExit) as e:
        cli.main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and len(err.strip().splitlines()) == 1
    if suggestion:
        assert f"did you mean {suggestion}?" in err, err


def test_top_level_help_lists_every_experiment(capsys):
    from glassdist.experiments import EXPERIMENTS

    with pytest.raises(SystemExit):
        cli.main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert len(EXPERIMENTS) == 5
    assert all(name in text.split("experiment", 1)[1] for name in EXPERIMENTS), text


@pytest.mark.parametrize("out", ["", "   "])
def test_an_empty_out_exits_2(pair, tmp_path, out):
    r = _cli(*_analyze(pair, out), cwd=tmp_path)
    assert r.returncode == 2 and "--out" in r.stderr and "empty" in r.stderr and "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []  # nothing landed in the current folder


def test_an_out_name_too_long_for_the_file_system_exits_2(pair, tmp_path):
    r = _cli(*_analyze(pair, tmp_path / ("x" * 300)))
    assert r.returncode == 2 and "name too long" in r.stderr.lower() and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("name, content", [("summary.json", b'{"my": "own notes"}\n'),
                                           ("phi_eff.png", b"my own picture"),
                                           ("statistics.csv", b"a,b\n1,2\n")])
def test_a_users_own_file_in_out_survives_with_exit_2(pair, tmp_path, name, content):
    out = tmp_path / "out"
    out.mkdir()
    (out / name).write_bytes(content)
    r = _cli(*_analyze(pair, out))
    assert r.returncode == 2, r.stderr
    assert name in r.stderr and "not written by glassdist" in r.stderr and "Traceback" not in r.stderr
    assert (out / name).read_bytes() == content
    assert [p.name for p in out.iterdir()] == [name]  # refused before any work


def test_the_tools_own_files_are_rewritten_but_an_edited_one_is_not(pair, tmp_path):
    out = tmp_path / "out"
    assert _cli(*_analyze(pair, out)).returncode == 0
    assert _cli(*_analyze(pair, out)).returncode == 0  # every file recorded with its SHA-256: a re-run is fine
    figure = out / "phi_eff.png"
    edited = figure.read_bytes() + b"annotated"
    figure.write_bytes(edited)
    r = _cli(*_analyze(pair, out))
    assert r.returncode == 2 and "phi_eff.png" in r.stderr
    assert figure.read_bytes() == edited


def test_debug_keeps_exit_2_for_bad_input_and_adds_the_traceback(pair, tmp_path):
    r = _child("--debug", "analyze", pair / "pane.png", "--pitch-mm", 2, "--distance-m", 1, "--mask",
               tmp_path / "missing.png", "--out", tmp_path / "o")
    assert r.returncode == 2
    assert "Traceback" in r.stderr and r.stderr.strip().splitlines()[-1].startswith("glassdist: error:")


def test_a_full_disk_under_report_export_exits_2_saying_what_is_needed(pair, tmp_path, monkeypatch, capsys):
    """ENOSPC while writing the exports: exit 2 with the space the outputs need, no traceback."""
    from glassdist.storage import fields

    real = fields.atomic_write

    def full_disk(path, write, **kw):
        if path.name == "fields.npz":
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, write, **kw)

    monkeypatch.setattr(fields, "atomic_write", full_disk)
    code = cli.main([str(a) for a in _analyze(pair, tmp_path / "o", "--report", "--export", "--quiet")])
    err = capsys.readouterr().err
    assert code == 2, err
    m = re.search(r"no space left .* need up to (\d+) MB", err)
    assert m and int(m.group(1)) >= 1, err
    assert "Traceback" not in err


_HEAVY = ("matplotlib", "sqlalchemy", "cv2", "scipy.ndimage", "skimage", "glassdist.analyzer.pipeline",
          "glassdist.render.tracer")


@pytest.mark.parametrize("argv", [["--help"], ["analyze", "missing.png", "--pitch-mm", "5", "--distance-m", "0.5",
                                               "--out", "out"]], ids=["help", "refused"])
def test_help_and_a_refused_input_load_no_analysis_or_plotting_stack(argv, tmp_path):
    """The package's names load on first use: neither the help nor a refused input pays for the stacks."""
    code = ("import sys\nfrom glassdist.cli import main\ntry:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
            f"print(sorted(m for m in {_HEAVY!r} if m in sys.modules))")
    r = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, cwd=tmp_path)
    assert r.stdout.strip().splitlines()[-1] == "[]", r.stdout[-500:] + r.stderr[-500:]


_IMPORTS_OF = """
import importlib, json, sys
import glassdist._lazy as lazy
from glassdist import cli
from glassdist.storage import record
seen = {}
read = cli._read_inputs
def read_then_note(args):
    out = read(args)
    seen["before"] = set(sys.modules)
    return out
def stop(*a, **k):
    main = set(sys.modules) - seen["before"]  # what the analysis imported, in the main thread
    before = set(sys.modules)
    for name in (*cli._OUTPUT_STACKS, *cli._HISTORY_STACK):
        importlib.import_module(name)
    print(json.dumps([sorted(main), sorted(set(sys.modules) - before)]))
    raise SystemExit(0)
cli._read_inputs, record.build_record = read_then_note, stop
lazy.import_in_background = lambda *names: None
cli.main(sys.argv[1:])
"""


def test_the_background_imports_share_no_module_with_the_analysis(pair, tmp_path):
    """analyze imports the output stage's stacks in a thread while the main thread analyses: no module is imported
    by both, so neither can wait on an import the other holds."""
    import json

    r = subprocess.run([sys.executable, "-c", _IMPORTS_OF, *map(str, _analyze(pair, tmp_path / "o"))],
                       capture_output=True, text=True)
    main, background = (set(s) for s in json.loads(r.stdout.strip().splitlines()[-1]))
    assert len(main) > 100 and {"matplotlib.figure", "sqlalchemy.orm"} <= background
    assert not main & background
