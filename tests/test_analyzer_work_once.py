"""Work the analyzer once did twice is done once: each computation counted over one analysis (as test_run_io counts I/O).

- the photo's full FFT: F1-F3 transform it, F5 reads its basebands on its own grid from that one spectrum;
- F1's carrier search on the photo in the Comparative Method (which takes the reference's carriers): only the
  pattern check's, on its crop, which also says when the photo shows no grid;
- the Direct checks' samples beyond the guard band: one distance transform, handed to the three checks;
- A1's Jacobian of the baseline (``logical_jacobian`` on the analysis grid): once, read by A2-A3, the Direct checks
  and the bulk channel.
"""

from __future__ import annotations

import sys
import types
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from glassdist.analyzer import fourier
from glassdist.analyzer.pipeline import analyze, prepare_reference
from glassdist.errors import InputError

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real-checkerboard-water"
needs_photos = pytest.mark.skipif(not (DATA / "distorted_waves.bmp").exists(),
                                  reason=f"the real photos are not at {DATA}")


class _Counted:
    """Counting wrappers of functions, patched into every analyzer module that holds them."""

    def __init__(self, mp: pytest.MonkeyPatch, photo: np.ndarray):
        self.calls: Counter[str] = Counter()
        self.photo = photo
        orig_fft, orig_find = fourier.compute_spectrum, fourier.find_carriers
        from glassdist.analyzer import homography

        orig_jac = homography.logical_jacobian

        def compute_spectrum(image, *a, **k):
            img = np.asarray(image)
            if img.shape == photo.shape and np.array_equal(img, photo):
                self.calls["photo FFT"] += 1
            return orig_fft(image, *a, **k)

        def find_carriers(*a, **k):
            self.calls["find_carriers"] += 1
            return orig_find(*a, **k)

        def logical_jacobian(H, lens, x, y):
            if np.ndim(x) == 2:  # on a grid (Block I's own checks read it at its points)
                self.calls["logical_jacobian on the grid"] += 1
            return orig_jac(H, lens, x, y)

        mp.setattr(fourier, "compute_spectrum", compute_spectrum)
        mp.setattr(fourier, "find_carriers", find_carriers)
        for name, mod in list(sys.modules.items()):
            if name.startswith("glassdist.analyzer.") and getattr(mod, "logical_jacobian", None) is orig_jac:
                mp.setattr(mod, "logical_jacobian", logical_jacobian)
        from scipy import ndimage

        from glassdist.analyzer import direct_checks

        def edt(*a, **k):
            self.calls["guard-band distance transform"] += 1
            return ndimage.distance_transform_edt(*a, **k)

        mp.setattr(direct_checks, "ndimage", types.SimpleNamespace(distance_transform_edt=edt))
        from glassdist.analyzer import plausibility

        # the swapped-pair check runs on every reference (the real one's spread is under the floor): it reads
        # the photo's grid spread from F1's spectrum, not from a transform of its own
        mp.setattr(plausibility, "SWAP_FLOOR", 0.0)


def _photos():
    from glassdist.io import read_image

    img = read_image(DATA / "distorted_waves.bmp", dtype=np.float32)
    ref = read_image(DATA / "reference.png", dtype=np.float32)
    return img, ref


@pytest.fixture(scope="module")
def counted_runs():
    img, ref = _photos()
    refm = prepare_reference(ref, pattern="checkerboard")
    out = {}
    for method, reference in (("comparative", refm), ("direct", None)):
        mp = pytest.MonkeyPatch()
        c = _Counted(mp, img)
        try:
            out[method] = (analyze(img, pitch_mm=5.0, distance_m=1.0, reference=reference, pattern="checkerboard"),
                           c.calls)
        finally:
            mp.undo()
    return out


@needs_photos
@pytest.mark.parametrize("method", ["comparative", "direct"])
def test_the_photo_is_transformed_once(counted_runs, method):
    res, calls = counted_runs[method]
    assert res.demodulations > 1  # F5 ran: it once transformed the photo a second time
    assert calls["photo FFT"] == 1


@needs_photos
def test_the_comparative_photo_is_searched_for_carriers_once(counted_runs):
    _, calls = counted_runs["comparative"]
    assert calls["find_carriers"] == 1  # the pattern check's; the reference's carriers are used


@needs_photos
def test_the_direct_checks_share_one_guard_band(counted_runs):
    res, calls = counted_runs["direct"]
    assert res.method == "direct"
    assert calls["guard-band distance transform"] == 1


@needs_photos
@pytest.mark.parametrize("method", ["comparative", "direct"])
def test_the_jacobian_is_built_once(counted_runs, method):
    _, calls = counted_runs[method]
    assert calls["logical_jacobian on the grid"] == 1


def test_a_comparative_photo_without_a_grid_is_refused():
    """The carrier search the Comparative Method no longer repeats on the full photo still refuses a photo without a grid."""
    from glassdist.synthetic import synthetic_capture

    cap = synthetic_capture((192, 256), pitch_mm=10.0, mm_per_px=1.25)
    rng = np.random.default_rng(0)
    blank = (0.5 + 0.05 * rng.standard_normal(cap.image.shape)).astype(np.float32)
    with pytest.raises(InputError, match="grid|periodic"):
        analyze(blank, pitch_mm=10.0, distance_m=2.0, reference=cap.reference)


def test_the_pattern_is_read_once_per_photo(tmp_path, monkeypatch):
    """``glassdist analyze`` decides 'auto' from the photo before the analysis, which checks it on the same photo:
    the photo's spectrum is read for its pattern once (it was twice)."""
    from glassdist import cli
    from glassdist.analyzer import pattern
    from glassdist.io import write_png16
    from glassdist.synthetic import synthetic_capture

    cap = synthetic_capture((256, 320), pitch_mm=4.0, mm_per_px=0.5, pattern="checkerboard")
    write_png16(tmp_path / "photo.png", cap.image)
    calls: Counter[str] = Counter()
    orig = fourier.compute_spectrum

    def counted(image, *a, **k):
        if np.shape(image) == (256, 256):  # the pattern check's centred square crop (the photo is 256 x 320)
            calls["pattern spectrum"] += 1
        return orig(image, *a, **k)

    monkeypatch.setattr(fourier, "compute_spectrum", counted)
    monkeypatch.setattr(pattern, "_EVIDENCE", {}, raising=False)
    monkeypatch.setenv("GLASSDIST_DB", str(tmp_path / "history.sqlite"))
    status = cli.main(["analyze", str(tmp_path / "photo.png"), "--pitch-mm", "4", "--distance-m", "1",
                       "--out", str(tmp_path / "out")])
    assert status == 0
    assert calls["pattern spectrum"] == 1
