import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "examples" / "data"


@pytest.fixture(scope="session")
def real_data():
    """The bundled real photos (checkerboard through disturbed water), grey float in [0, 1]."""
    from glassdist.io import read_image

    return {
        "reference": read_image(DATA / "reference.png"),
        "waves": read_image(DATA / "distorted_waves.bmp"),
        "ring": read_image(DATA / "distorted_floating_ring.bmp"),
    }


def truth_channels(cap, res, *, labels=None):
    """The true displacement through the same evaluation stack (same N, sigma, region) as ``res``."""
    from glassdist.analyzer import evaluate_displacement

    return evaluate_displacement(
        cap.displacement_mm, res.valid, distance_m=res.distance_m, mm_per_px=res.mm_per_px,
        detrend_degree=res.detrend_degree, sigma_mm=res.sigma_mm, jacobian=cap.jacobian,
    )


def agreement(measured, truth, valid):
    """(ratio of mean |.|, Pearson correlation) over ``valid``."""
    a = measured[valid]
    b = truth[valid]
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = a[ok], b[ok]
    return float(np.mean(np.abs(a)) / np.mean(np.abs(b))), float(np.corrcoef(a, b)[0, 1])
