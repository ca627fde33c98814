import json
import os
from pathlib import Path

import pytest

# The suite's parallelism is pytest-xdist's workers, one per core: in each worker, and in the
# glassdist processes it starts, BLAS and OpenMP run one thread, as on a Dask worker
# (glassdist.distributed). Two workers that each wake a BLAS thread per core wait on each other:
# the accuracy files (test_lens, test_validate, test_reflection, test_analyzer_quality) took
# 104 s on 2 workers instead of 75 s. Set before numpy is first imported, when it reads them.
if int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) > 1:
    for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

os.environ.setdefault("MPLBACKEND", "Agg")

# The results history of every run the tests make goes to a temporary database, never the user's.
from _history_isolation import isolated_history_db  # noqa: E402,F401

REPO = Path(__file__).resolve().parents[1]
#: The project's own example photos, rendered by its tracer (scripts/render_examples.py).
EXAMPLES = REPO / "examples" / "images"
#: Real photographs (a checkerboard seen through disturbed water; reference.png, distorted_waves.bmp,
#: distorted_floating_ring.bmp). They come from another repository, so they are never in this tree:
#: they are read from the shared data folder beside the repository (CI has it).
DATA = REPO.parent / "shared" / "data" / "real-checkerboard-water"
REAL_PHOTOS_ABSENT = (f"needs the real photographs in {DATA} (the shared data folder beside the repository), "
                      "which is absent here")
#: Marks a test that reads :data:`DATA`: skipped, with the reason, where the folder is absent.
needs_real_photos = pytest.mark.skipif(not (DATA / "reference.png").is_file(), reason=REAL_PHOTOS_ABSENT)


def real_photos() -> Path:
    """The folder of the real photographs (:data:`DATA`); skips the calling test where it is absent."""
    if not (DATA / "reference.png").is_file():
        pytest.skip(REAL_PHOTOS_ABSENT)
    return DATA


@pytest.fixture(scope="session")
def real_data():
    """The real photos (checkerboard through disturbed water), grey float in [0, 1]; skips where absent."""
    from glassdist.io import read_image

    real_photos()
    return {
        "reference": read_image(DATA / "reference.png"),
        "waves": read_image(DATA / "distorted_waves.bmp"),
        "ring": read_image(DATA / "distorted_floating_ring.bmp"),
    }


def child_env():
    """This environment for a child ``glassdist`` process: this tree's ``src`` first on PYTHONPATH, Agg plots."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO / "src") + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env["MPLBACKEND"] = "Agg"
    return env


def run_cli(*args, cwd=None):
    """``glassdist ARGS`` run in this process (``glassdist.cli.main``), as a ``subprocess.CompletedProcess``.

    The command's own logic, exit status and output, without a child process's start-up
    (imports and a first figure's fonts: about 3 s of a small run). What only a process of
    its own shows is tested with one: the console script and ``python -m glassdist``
    (``test_contracts.py``), exit 1 with and without ``--debug``, Ctrl-C, a folder locked by
    another process, the documented commands as written (``test_docs_commands.py``).
    ``cwd``: the folder relative paths are read from, as the child's working folder.
    """
    import contextlib
    import io
    import subprocess

    from glassdist.cli import exit_status, main

    argv = [str(a) for a in args]
    out, err = io.StringIO(), io.StringIO()
    here = os.getcwd()
    try:
        if cwd is not None:
            os.chdir(cwd)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(argv)
            except SystemExit as exc:  # argparse: --help, --version, option errors
                code = exit_status(exc)
    finally:
        os.chdir(here)
    return subprocess.CompletedProcess(["glassdist", *argv], code, out.getvalue(), err.getvalue())


def truth_channels(cap, res):
    """The true displacement of ``cap`` evaluated independently of the analyzer (``tests/_truth.py``).

    Same detrend degree, smoothing scale, distance and region (``res.valid``) as ``res``;
    detrend, smoothing and channels written out in the test helper, not the analyzer's stack.
    """
    from _truth import truth_for

    return truth_for(cap, res)


def agreement(measured, truth, valid):
    """(ratio of mean |.|, Pearson correlation) over ``valid``."""
    a = measured[valid]
    b = truth[valid]
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = a[ok], b[ok]
    return float(np.mean(np.abs(a)) / np.mean(np.abs(b))), float(np.corrcoef(a, b)[0, 1])


def write_lens_pair(root):
    """A small synthetic pane (a converging lens, -100 mD at its centre) and its reference as 16-bit PNGs.

    Writes ``root/pane.png`` and ``root/reference.png`` (160 x 160 px, 2 mm pitch, 0.25 mm per px).
    """
    from glassdist.io import write_png16
    from glassdist.synthetic import lens_displacement, synthetic_capture

    cap = synthetic_capture((160, 160), pitch_mm=2.0, mm_per_px=0.25,
                            displacement=lens_displacement(0.05, 1.0, radius_mm=7.0), rng=0)
    write_png16(root / "pane.png", cap.image)
    write_png16(root / "reference.png", cap.reference)
    return root


@pytest.fixture(scope="session")
def real_pane_outputs(tmp_path_factory):
    """Output folders of real ``glassdist analyze`` runs on the small lens pair (the failing one with ``--report``).

    ``{"none": folder, "PASS": folder, "FAIL": folder}``: without a specification, with one the
    pane passes (p95 |phi_eff| <= 1e5 mD) and with one it fails (<= 1 mD). About a second each:
    batch tests replay them instead of inventing a summary's layout.
    """
    from glassdist.cli import main

    root = write_lens_pair(tmp_path_factory.mktemp("real_pane"))
    limits, codes = {"PASS": 1e5, "FAIL": 1.0}, {"none": 0, "PASS": 0, "FAIL": 3}
    out = {}
    for verdict, code in codes.items():
        args = ["analyze", str(root / "pane.png"), "--reference", str(root / "reference.png"), "--pitch-mm", "2",
                "--distance-m", "1", "--out", str(root / verdict), "-q"] + (["--report"] if verdict == "FAIL" else [])
        if verdict in limits:
            spec = root / f"{verdict}.json"
            spec.write_text(json.dumps({"name": verdict.lower(), "criteria": [
                {"channel": "phi_eff", "statistic": "p95_abs", "max_mD": limits[verdict]}]}))
            args += ["--spec", str(spec)]
        assert main(args) == code, verdict
        out[verdict] = root / verdict
    return out


#: The factory protocol for the real photographs (``../shared/data/real-checkerboard-water``, 1024 px, a 5 mm
#: checkerboard, the pane assumed 730 x 730 mm filling the photo): the specification their acceptance tests judge
#: with (the project's own example specification is written for its rendered example, examples/factory).
REAL_PAIR_SPEC = {
    "name": "Example line acceptance (Comparative, L = 1 m, 5 mm checkerboard, sigma 2 periods, N = 2)",
    "description": ("Area-change and shape-change limits on the detrended local distortion, tighter in the vision area "
                    "than along the edge."),
    "protocol": {
        "method": "comparative",
        "distance_m": 1.0,
        "pitch_mm": 5.0,
        "pattern": "checkerboard",
        "sigma_periods": 2,
        "detrend_degree": 2,
        "min_px_per_period": 6
    },
    "pane": {
        "corners_frac": [
            [
                0,
                0
            ],
            [
                1,
                0
            ],
            [
                1,
                1
            ],
            [
                0,
                1
            ]
        ],
        "size_mm": [
            730,
            730
        ]
    },
    "zones": [
        {
            "name": "edge",
            "edge_band_mm": 100,
            "min_valid_percent": 40
        },
        {
            "name": "vision",
            "inset_mm": 100,
            "min_valid_percent": 60
        }
    ],
    "criteria": [
        {
            "channel": "phi_eff",
            "statistic": "p95_abs",
            "max_mD": 40,
            "zone": "vision"
        },
        {
            "channel": "phi_shear",
            "statistic": "p95_abs",
            "max_mD": 40,
            "zone": "vision"
        },
        {
            "channel": "phi_eff",
            "statistic": "area_over",
            "threshold_mD": 100,
            "max_percent": 0.5,
            "zone": "vision"
        },
        {
            "channel": "phi_eff",
            "statistic": "p95_abs",
            "max_mD": 80,
            "zone": "edge"
        },
        {
            "channel": "phi_shear",
            "statistic": "p95_abs",
            "max_mD": 80,
            "zone": "edge"
        }
    ],
    "min_valid_percent": 50,
    "figures": {
        "colour_limit": "spec"
    }
}
