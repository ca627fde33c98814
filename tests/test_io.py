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


# --------------------------------------------------------------------------- what a photo file may not hold


def test_planes_of_one_tiff_page_are_a_stack_not_colour(tmp_path, grid):
    """Several grey planes in one TIFF page (separate or contiguous samples, or depth) are refused, not read from the first."""
    stack = np.stack([grid, 1 - grid, grid]).astype(np.float32)
    cases = {"separate": dict(photometric="minisblack", planarconfig="separate"),
             "contig": dict(photometric="minisblack", planarconfig="contig")}
    for name, kw in cases.items():
        data = stack if name == "separate" else np.moveaxis(stack, 0, -1)
        tifffile.imwrite(tmp_path / f"{name}.tif", data, **kw)
        with pytest.raises(InputError, match="3 image planes in one page"):
            read_image(tmp_path / f"{name}.tif")
    # RGB and grey + alpha (opaque) are colour and transparency, not planes
    tifffile.imwrite(tmp_path / "rgb.tif", np.moveaxis(stack, 0, -1), photometric="rgb")
    assert read_image(tmp_path / "rgb.tif").shape == grid.shape
    tifffile.imwrite(tmp_path / "ga.tif", np.dstack([grid, np.ones_like(grid)]).astype(np.float32),
                     photometric="minisblack", extrasamples=[2])
    assert np.allclose(read_image(tmp_path / "ga.tif"), grid, atol=1e-6)


def test_black_and_white_photo_is_refused_but_a_black_and_white_mask_is_read(tmp_path, grid):
    from glassdist import read_mask

    tifffile.imwrite(tmp_path / "bw.tif", grid > 0.5)
    with pytest.raises(InputError, match="black and white only"):
        read_image(tmp_path / "bw.tif")
    assert read_mask(tmp_path / "bw.tif", grid.shape).sum() == np.count_nonzero(grid > 0.5)


@pytest.mark.parametrize("scale", [255.0, 65535.0, -1.0])
def test_float_image_outside_zero_one_is_refused(tmp_path, grid, scale):
    """A float TIFF scaled to 0..255 or 0..65535 (or negative) would pass every saturation check as unsaturated."""
    tifffile.imwrite(tmp_path / "f.tif", (grid * scale).astype(np.float32))
    with pytest.raises(InputError, match="floating-point values from .* scale it to"):
        read_image(tmp_path / "f.tif")
    tifffile.imwrite(tmp_path / "ok.tif", np.clip(grid + 0.04, 0, 1.04).astype(np.float32))  # within the slack
    read_image(tmp_path / "ok.tif")


def test_rgba_png_transparency_is_refused_and_opaque_rgba_read_as_rgb(tmp_path, grid):
    """BGRA from the decoder is RGBA after the channel swap (alpha last, not first); transparency is an error."""
    g = np.round(grid * 255).astype(np.uint8)
    blue = np.zeros_like(g)
    bgra = np.dstack([g, blue, blue, np.full_like(g, 255)])  # blue channel = the grid, opaque
    assert cv2.imwrite(str(tmp_path / "opaque.png"), bgra)
    assert np.allclose(read_image(tmp_path / "opaque.png"), 0.114 * g / 255.0, atol=1e-9)  # BT.601 blue weight
    bgra[:, : g.shape[1] // 2, 3] = 0
    assert cv2.imwrite(str(tmp_path / "clear.png"), bgra)
    with pytest.raises(InputError, match=r"transparent pixels \(50% of its alpha channel"):
        read_image(tmp_path / "clear.png")


def test_a_plain_gradient_is_told_no_grid(tmp_path):
    """A brightness gradient (no grid at all) is not 'one family of grid lines', nor a grid too coarse for the image."""
    rng = np.random.default_rng(0)
    y, x = np.mgrid[0:240, 0:320]
    for ramp in (0.1 + 0.8 * x / 320, 0.1 + 0.4 * x / 320 + 0.4 * y / 240, 0.2 + 0.6 * np.hypot(x - 160, y - 120) / 200):
        with pytest.raises(InputError, match="no grid pattern found") as err:
            analyze(ramp + rng.normal(0, 0.01, ramp.shape), pitch_mm=5.0, distance_m=1.0)
        assert "one family" not in str(err.value) and "too small" not in str(err.value)
    lines = 0.5 + 0.3 * np.cos(2 * np.pi * x / 10) + rng.normal(0, 0.01, x.shape)  # one real family keeps its message
    with pytest.raises(InputError, match="only one family of grid lines"):
        analyze(lines, pitch_mm=5.0, distance_m=1.0)
