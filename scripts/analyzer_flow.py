"""Follow one Comparative run as data: the analyzer modules ``pipeline.py`` calls into, in order.

Usage (``PYTHONPATH`` names the tree to follow, so an older checkout can be followed the same way)::

    PYTHONPATH=src python scripts/analyzer_flow.py OUT.json

The run: the real waves photo against its reference (``../shared/data/real-checkerboard-water``),
pitch 5 mm, L = 1 m, the reference prepared once beforehand (as the command line does). A
``sys.setprofile`` hook records every call of a module-level function of ``glassdist.analyzer``
(records' methods and properties, comprehensions left out) whose caller is ``pipeline.py``;
consecutive calls into one module are collapsed into ``[module, count]``. Written: that sequence,
the number of calls, how many of them go to ``fourier.py``, and how often control comes back into
``pipeline.py`` from another module (``pipeline_entries``) over the whole run.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from glassdist.analyzer import pipeline
from glassdist.io import read_image

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real-checkerboard-water"
PKG = "glassdist.analyzer."


def _module(frame) -> str | None:
    name = frame.f_globals.get("__name__", "")
    return name[len(PKG):] if name.startswith(PKG) else None


def _stage(frame) -> bool:
    """A module-level function (not a record's method or property, not a comprehension)."""
    q = frame.f_code.co_qualname
    return "." not in q and not q.startswith("<")


def follow() -> dict:
    img = read_image(DATA / "distorted_waves.bmp", dtype=np.float32)
    refm = pipeline.prepare_reference(read_image(DATA / "reference.png", dtype=np.float32))
    direct: list[str] = []  # modules pipeline.py calls into directly, in order
    current: list[str] = []  # the module running, over time (call and return events)

    def prof(frame, event, arg):
        if event not in ("call", "return"):
            return
        m = _module(frame)
        if m is None or not _stage(frame):
            return
        if event == "call":
            if frame.f_back is not None and _module(frame.f_back) == "pipeline" and m != "pipeline":
                direct.append(m)
            here = m
        else:
            here = frame.f_back and _module(frame.f_back)
            if here is None:
                return
        if not current or current[-1] != here:
            current.append(here)

    sys.setprofile(prof)
    try:
        res = pipeline.analyze(img, pitch_mm=5.0, distance_m=1.0, reference=refm)
    finally:
        sys.setprofile(None)
    collapsed: list[list] = []
    for m in direct:
        if collapsed and collapsed[-1][0] == m:
            collapsed[-1][1] += 1
        else:
            collapsed.append([m, 1])
    return {"direct_calls_from_pipeline": collapsed, "n_direct_calls": len(direct),
            "fourier_called_from_pipeline": sum(1 for m in direct if m == "fourier"),
            "pipeline_entries": sum(1 for m in current if m == "pipeline"), "module_switches": len(current) - 1,
            "demodulations": res.demodulations}


if __name__ == "__main__":
    if not (DATA / "distorted_waves.bmp").exists():
        raise SystemExit(f"the real photos are not at {DATA}")
    Path(sys.argv[1]).write_text(json.dumps(follow(), indent=1) + "\n")
