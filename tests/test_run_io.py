"""Counted I/O of one ``glassdist analyze --spec examples/factory/spec.json --report`` run, in process.

A counting hook records every file opened (``open``, ``io.open``, ``os.open``), every
rename into place (``os.replace``) and every call of the functions that must run once
(``sys.setprofile``: calls are counted wherever the function was imported to). The run
must read each input once, write ``summary.json`` once and never read back what it wrote.
"""

from __future__ import annotations

import builtins
import hashlib
import io
import json
import os
import sys
from collections import Counter
from pathlib import Path

import pytest

from conftest import EXAMPLES
from glassdist import cli

FACTORY_SPEC = Path(__file__).resolve().parents[1] / "examples" / "factory" / "spec.json"


class IOCounter:
    """Counts opens per path and mode, renames per target and calls per function while active."""

    def __init__(self, functions):
        self.opens = Counter()  # (resolved path, "r" or "w")
        self.replaced = Counter()
        self.calls = Counter()
        self._codes = {f.__code__: f.__qualname__ for f in functions}

    @staticmethod
    def _key(path):
        try:
            return str(Path(os.fsdecode(path)).resolve())
        except (TypeError, ValueError):
            return None  # a file descriptor or a file object

    def _open(self, real):
        def counted(file, mode="r", *args, **kwargs):
            fh = real(file, mode, *args, **kwargs)  # counted once it opened
            key = self._key(file)
            if key is not None:
                self.opens[key, "w" if any(c in mode for c in "wax+") else "r"] += 1
            return fh
        return counted

    def _os_open(self, real):
        def counted(path, flags, *args, **kwargs):
            fd = real(path, flags, *args, **kwargs)
            key = self._key(path)
            if key is not None and not os.path.isdir(key):
                self.opens[key, "w" if flags & (os.O_WRONLY | os.O_RDWR) else "r"] += 1
            return fd
        return counted

    def _replace(self, real):
        def counted(src, dst, *args, **kwargs):
            real(src, dst, *args, **kwargs)
            self.replaced[self._key(dst)] += 1
        return counted

    def _profile(self, frame, event, arg):
        if event == "call" and frame.f_code in self._codes:
            self.calls[self._codes[frame.f_code]] += 1

    def reads_of(self, path) -> int:
        return self.opens[str(Path(path).resolve()), "r"]

    def patch(self, monkeypatch):
        monkeypatch.setattr(builtins, "open", self._open(builtins.open))
        monkeypatch.setattr(io, "open", self._open(io.open))
        monkeypatch.setattr(os, "open", self._os_open(os.open))
        monkeypatch.setattr(os, "replace", self._replace(os.replace))
        sys.setprofile(self._profile)

    @staticmethod
    def stop():
        sys.setprofile(None)


@pytest.fixture(scope="module")
def counted_run(tmp_path_factory):
    """One factory run (Comparative, the bundled photos, the example specification, with the report), counted.

    With a ``--params`` file setting what the specification pins (``detrend_degree`` 2): read once, where the
    options' resolution, the specification's checks and the analysis all take its values.
    """
    from glassdist.acceptance.spec import check_capture, spec_limits
    from glassdist.analyzer.pattern import detect_pattern
    from glassdist.fs import file_sha256
    from glassdist.io import camera_metadata, read_image, read_photo

    out = tmp_path_factory.mktemp("factory") / "out"
    params = out.parent / "params.json"
    params.write_text('{"detrend_degree": 2}')
    counter = IOCounter([spec_limits, check_capture, file_sha256, read_photo, read_image, camera_metadata,
                         detect_pattern])
    mp = pytest.MonkeyPatch()
    counter.patch(mp)
    try:
        code = cli.main(["analyze", str(EXAMPLES / "factory_pane.png"), "--reference", str(EXAMPLES / "factory_reference.png"),
                         "--spec", str(FACTORY_SPEC), "--params", str(params), "--report", "--no-history", "--quiet",
                         "--out", str(out)])
    finally:
        counter.stop()
        mp.undo()
    return counter, code, out


def test_the_run_is_the_documented_factory_run(counted_run):
    counter, code, out = counted_run
    assert code == 3  # the example specification FAILS (examples/factory/README.md)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["verdict"]["result"] == "FAIL"


def test_each_input_is_read_once_and_hashed_from_the_bytes_read(counted_run):
    counter, _, out = counted_run
    assert counter.reads_of(FACTORY_SPEC) == 1
    assert counter.reads_of(out.parent / "params.json") == 1  # parsed once: the protocol's and the analysis's values
    assert counter.reads_of(EXAMPLES / "factory_pane.png") == 1  # decode, SHA-256 and EXIF from one read
    assert counter.reads_of(EXAMPLES / "factory_reference.png") == 1
    summary = json.loads((out / "summary.json").read_text())
    for name, key in (("factory_pane.png", "image_sha256"), ("factory_reference.png", "reference_sha256")):
        assert summary["inputs"][key] == hashlib.sha256((EXAMPLES / name).read_bytes()).hexdigest()
    assert summary["verdict"]["spec_sha256"] == hashlib.sha256(FACTORY_SPEC.read_bytes()).hexdigest()


def test_summary_is_written_once_and_no_output_is_read_back(counted_run):
    counter, _, out = counted_run
    out = out.resolve()
    assert counter.replaced[str(out / "summary.json")] == 1
    read_back = sorted(p for (p, mode), n in counter.opens.items() if mode == "r" and Path(p).parent == out)
    assert read_back == []  # summary.json, result.npz, figures: none read back, none re-read to hash it
    assert counter.calls["file_sha256"] == 0
    written = json.loads((out / "summary.json").read_text())["outputs"]
    for name, rec in written.items():  # the digests taken while writing are those of the files
        assert hashlib.sha256((out / name).read_bytes()).hexdigest() == rec["sha256"], name


def test_derived_once_checked_once(counted_run):
    counter, _, _ = counted_run
    assert counter.calls["spec_limits"] == 1
    assert counter.calls["check_capture"] == 1
    assert counter.calls["read_photo"] == 2 and counter.calls["read_image"] == 0  # photo and reference
    assert counter.calls["detect_pattern"] == 1  # the factory protocol pins the pattern: checked once


def test_counter_sees_a_second_read():
    """The hook can fail: a file read twice is counted twice, a function called twice counted twice."""
    from glassdist.acceptance.spec import spec_limits

    counter = IOCounter([spec_limits])
    mp = pytest.MonkeyPatch()
    counter.patch(mp)
    try:
        for _ in range(2):
            with open(FACTORY_SPEC, "rb") as fh:
                fh.read()
            FACTORY_SPEC.read_bytes()
    finally:
        counter.stop()
        mp.undo()
    assert counter.reads_of(FACTORY_SPEC) == 4
