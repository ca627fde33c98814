"""Image input: formats, bit depths, colour; degraded input gives warnings, not silence."""

import cv2
import numpy as np
import pytest
import tifffile

from glassdist import analyze, read_image
from glassdist.errors import InputError
from glassdist.synthetic import synthetic_capture


@pytest.fixture(scope="module")
def grid():
    return synthetic_capture((128, 160), pitch_mm=8.0, mm_per_px=1.0).image


@pytest.mark.parametrize("ext,dtype,colour", [(".png", np.uint8, False), (".png", np.uint16, True), (".tif", np.uint16, False),
                                             (".bmp", np.uint8, True), (".jpg", np.uint8, False), (".tiff", np.float32, False)])
def test_formats_round_trip(tmp_path, grid, ext, dtype, colour):
    f = tmp_path / f"img{ext}"
    if np.issubdtype(dtype, np.integer):
        data = np.round(grid * np.iinfo(dtype).max).astype(dtype)
    else:
        data = grid.astype(dtype)
    if colour:
        data = np.stack([data] * 3, axis=-1)
    if ext.startswith(".tif"):
        tifffile.imwrite(f, data)
    else:
        assert cv2.imwrite(str(f), data)
    img = read_image(f)
    assert img.shape == grid.shape and img.dtype == np.float64
    tol = 0.05 if ext == ".jpg" else 1.0 / 255
    assert np.abs(img - grid).mean() < tol


def test_unreadable_file_is_a_clear_error(tmp_path):
    f = tmp_path / "broken.png"
    f.write_bytes(b"not an image")
    with pytest.raises(InputError, match="cannot decode"):
        read_image(f)
    with pytest.raises(InputError, match="unsupported extension"):
        read_image(tmp_path / "x.gif") if (tmp_path / "x.gif").write_bytes(b"GIF") else None


def test_low_contrast_and_occlusion_give_warnings_not_silence():
    cap = synthetic_capture((300, 360), pitch_mm=8.0, mm_per_px=1.0)
    img = 0.5 + 0.06 * (cap.image - 0.5)  # low contrast
    img[100:250, 80:300] = 0.3  # large opaque object
    res = analyze(img, pitch_mm=8.0, distance_m=10.0)
    assert any("contrast" in w for w in res.warnings)
    assert any("could be analysed" in w for w in res.warnings)
    assert not res.valid[120:230, 100:280].any()


@pytest.mark.parametrize("bits, ext", [(8, ".png"), (16, ".png"), (12, ".tif"), (10, ".tif")])
def test_single_precision_read_is_the_double_read_rounded(tmp_path, bits, ext):
    """``dtype=float32`` gives exactly the float64 values rounded (the analyzer's input), for every code value."""
    full = 2**bits - 1
    codes = np.arange(full + 1, dtype=np.uint8 if bits == 8 else np.uint16)
    img = np.resize(codes, (max(2, (full + 1) // 256), 256))
    path = tmp_path / f"all_codes{ext}"
    if ext == ".png":
        cv2.imwrite(str(path), img)
    else:
        tifffile.imwrite(path, img, bitspersample=bits)
    double, single = read_image(path), read_image(path, dtype=np.float32)
    assert double.dtype == np.float64 and single.dtype == np.float32
    assert np.array_equal(double, img / float(full))
    assert np.array_equal(single, (img / float(full)).astype(np.float32))
