import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

# The results history of every run the tests make goes to a temporary database, never the user's.
from _history_isolation import isolated_history_db  # noqa: E402,F401

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
