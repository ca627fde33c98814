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
