"""Warnings state the figures the outputs show: one computation, one formatting."""

import re

import numpy as np
import pytest

from conftest import REPO
from glassdist import analyze

REAL = REPO.parent / "shared" / "data" / "real-checkerboard-water"


def test_whole_period_offsets_print_without_a_negative_zero():
    """Offsets that are whole periods read '(0, 0)', never '(-0, -0)' (a float -0.0 formatted with a sign)."""
    from glassdist.analyzer.homography import _ambiguous_offsets

    offsets = np.array([[0.0, 0.0], [0.0, 0.0], [-0.0, -0.0], [-0.3, 4.6], [-2.0, 1.0]])
    said = _ambiguous_offsets(3.1, 4, offsets)
    assert said is not None
    assert "taken as (0, 0), (0, 5), (-2, 1) periods" in said and "-0" not in said


def test_strong_distortion_warning_states_the_quality_legends_shares():
    """The warning's excluded shares are the quality map legend's (result.quality_counts over the image), to the digit."""
    from glassdist.analyzer.region import EXCLUDED, LABELS
    from glassdist.io import read_image

    if not (REAL / "distorted_waves.bmp").exists():
        pytest.skip(f"the real photos are not here ({REAL}): they live in the shared data folder, not the repository")
    waves, ref = (read_image(REAL / n, dtype=np.float32) for n in ("distorted_waves.bmp", "reference.png"))
    res = analyze(waves, reference=ref, pitch_mm=5.0, distance_m=0.5, pattern="checkerboard", detrend_degree=3)
    (warning,) = [w for w in res.warnings if w.startswith("strong distortion")]
    counts = res.quality_counts()
    total = sum(counts.values())
    legend = {LABELS[k]: f"{100.0 * counts[LABELS[k]] / total:.1f}" for k in EXCLUDED}  # report.figures.plot_quality
    assert re.search(rf"{legend['beyond measurable distortion']}% of the region is beyond", warning), (warning, legend)
    for name in ("image edge", "occluded / low modulation"):
        assert f"{legend[name]}% {name}" in warning, (warning, legend)
