"""The far end: a small photo through strong schlieren, where almost nothing can be trusted.

The analysis is reported as such (statistics null, a warning saying why) and the command
exits 0, or 3 with a specification it cannot pass; never 1.
"""

import json

import numpy as np
import pytest
from scipy import ndimage

from conftest import run_cli
from glassdist import analyze
from glassdist.io import write_png16
from glassdist.synthetic import backdrop_pattern


def _schlieren(amplitude_px: float):
    """A 320 px checkerboard (5.7 px carrier period) seen through random schlieren of ~6 px correlation length."""
    rng = np.random.default_rng(4)
    yy, xx = np.mgrid[0:320, 0:320].astype(float)
    n = [ndimage.gaussian_filter(rng.normal(size=(320, 320)), 6) for _ in range(2)]
    n = [a / a.std() * amplitude_px for a in n]
    ref = backdrop_pattern(xx * 0.25, yy * 0.25, pitch_mm=1.0, pattern="checkerboard")
    img = backdrop_pattern((xx + n[0]) * 0.25, (yy + n[1]) * 0.25, pitch_mm=1.0, pattern="checkerboard")
    return img, ref


@pytest.fixture(scope="module")
def photos(tmp_path_factory):
    d = tmp_path_factory.mktemp("far")
    img, ref = _schlieren(2.5)
    write_png16(d / "img.png", img)
    write_png16(d / "ref.png", ref)
    (d / "spec.json").write_text(json.dumps(
        {"name": "far end", "criteria": [{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 40}]}))
    return d


_cli = run_cli  # in this process (conftest.run_cli)


ARGS = ("--pattern", "checkerboard", "--pitch-mm", "1", "--distance-m", "0.5", "--sigma-mm", "8")


def test_no_trusted_pixel_gives_null_statistics_and_says_why():
    img, ref = _schlieren(2.5)
    res = analyze(img, reference=ref, pattern="checkerboard", pitch_mm=1.0, distance_m=0.5, sigma_mm=8.0)
    assert res.valid.any() and not res.trusted.any()
    s = res.statistics()["phi_eff_mD"]
    assert s["n_valid"] == 0 and np.isnan(s["p95_abs"])
    assert any(w.startswith("no pixel is trusted") for w in res.warnings), res.warnings


def test_command_exits_0_without_and_3_with_a_spec(photos, tmp_path):
    run = _cli("analyze", photos / "img.png", "--reference", photos / "ref.png", *ARGS, "--out", tmp_path / "a")
    assert run.returncode == 0, run.stderr
    assert "no pixel is trusted" in run.stderr and "p95 |phi_eff| n/a" in run.stdout
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert summary["statistics"]["phi_eff_mD"]["p95_abs"] is None
    run = _cli("analyze", photos / "img.png", "--reference", photos / "ref.png", *ARGS, "--spec", photos / "spec.json",
               "--out", tmp_path / "b")
    assert run.returncode == 3, run.stderr
    assert "FAIL" in run.stdout
