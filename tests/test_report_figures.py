"""A4 figures: heatmaps, masks, histograms are drawn from arrays and return (fig, ax)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from conftest import DATA, needs_real_photos
from glassdist.acceptance.stats import shared_limit
from glassdist.report import figures


def known_fields(shape=(96, 128), *, eff_mD=-40.0, shear_mD=12.0, seed=0):
    """Simple known channels for the drawing functions: ``(phi_eff, phi_shear, axis_deg, valid)``.

    ``phi_eff`` is a Gaussian dip of depth ``eff_mD`` at the centre, ``phi_shear`` a
    constant ``shear_mD`` plus seeded noise, the axis 30 degrees; the top 8 rows are
    invalid (NaN).
    """
    rng = np.random.default_rng(seed)
    h, w = shape
    y, x = np.mgrid[0:h, 0:w]
    valid = np.ones(shape, bool)
    valid[:8] = False
    eff = eff_mD * np.exp(-((x - w / 2) ** 2 + (y - h / 2) ** 2) / (2 * (h / 6) ** 2))
    shear = shear_mD + rng.normal(0.0, 0.5, shape).clip(-shear_mD, None)
    axis = np.full(shape, 30.0)
    for f in (eff, shear, axis):
        f[~valid] = np.nan
    return SimpleNamespace(phi_eff_mD=eff, phi_shear_mD=shear, axis_deg=axis, valid=valid)


def test_save_channel_heatmaps_writes_pngs(tmp_path):
    """A real analysis (a small synthetic lens, Comparative Method), not a stand-in for one."""
    import glassdist
    from glassdist.synthetic import lens_displacement, synthetic_capture

    cap = synthetic_capture((160, 160), pitch_mm=2.0, mm_per_px=0.25,
                            displacement=lens_displacement(0.05, 1.0, radius_mm=7.0), rng=0)
    res = glassdist.analyze(cap.image, reference=cap.reference, pitch_mm=2.0, distance_m=1.0)
    paths = figures.save_channel_heatmaps(res, tmp_path)
    assert [p.name for p in paths] == ["phi_eff.png", "phi_shear.png", "axis.png"]
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_shared_limit_ignores_invalid_and_covers_both_channels():
    r = known_fields()
    v = shared_limit(r.phi_eff_mD, r.phi_shear_mD, valid=r.valid, percentile=100)
    assert v == pytest.approx(max(np.nanmax(np.abs(r.phi_eff_mD)), np.nanmax(r.phi_shear_mD)))
    assert shared_limit(np.full((4, 4), np.nan)) == 1.0


def test_diverging_limits_are_symmetric_and_sequential_start_at_zero():
    r = known_fields()
    _, ax = figures.plot_channel(r.phi_eff_mD, r.valid, signed=True, vmax=25.0)
    assert ax.images[0].get_clim() == (-25.0, 25.0)
    _, ax = figures.plot_channel(r.phi_shear_mD, r.valid, signed=False, vmax=25.0)
    assert ax.images[0].get_clim() == (0.0, 25.0)
    assert ax.figure.axes[-1].get_ylabel() == "mD"


def test_plots_accept_an_existing_axes():
    from matplotlib.figure import Figure

    r = known_fields()
    fig = Figure()
    axes = fig.subplots(2, 3)
    calls = [
        lambda ax: figures.plot_channel(r.phi_eff_mD, r.valid, ax=ax),
        lambda ax: figures.plot_axis(r.axis_deg, r.phi_shear_mD, r.valid, ax=ax),
        lambda ax: figures.plot_input(np.full(r.valid.shape, 0.5), r.valid, ax=ax),
        lambda ax: figures.plot_threshold_mask(r.phi_eff_mD, r.valid, limit_mD=20.0, ax=ax),
        lambda ax: figures.plot_histogram(r.phi_eff_mD, r.valid, limits_mD=[20.0], ax=ax),
    ]
    for call, ax in zip(calls, axes.flat):
        f, a = call(ax)
        assert f is fig and a is ax


def test_threshold_mask_title_reports_area_over_limit():
    field = np.zeros((10, 10))
    field[:, :3] = 5.0  # 30 % of the pixels over 4 mD
    _, ax = figures.plot_threshold_mask(field, None, limit_mD=4.0)
    assert "30 % of the trusted region" in ax.get_title()  # 4 significant figures, as the Results table


def test_heatmap_caption_speaks_of_trusted_pixels():
    """The caption's max |phi| is the statistics' (trusted pixels), not the guard band's larger values."""
    import re

    import glassdist
    from glassdist.acceptance.assess import assess
    from glassdist.report.maps import run_figures
    from glassdist.synthetic import synthetic_capture, wave_displacement

    cap = synthetic_capture((240, 320), pitch_mm=8.0, mm_per_px=1.0, displacement=wave_displacement(0.6, 90.0, 25.0))
    img = cap.image.copy()
    img[100:140, 140:180] = 0.5  # an opaque drop: excluded, with a guard band around it
    res = glassdist.analyze(img, pitch_mm=8.0, distance_m=10.0, reference=cap.reference)
    acc = assess(res)
    figs = {stem: caption for stem, caption, _ in run_figures(res, heatmaps=True, acceptance=acc)}
    for name, attr in (("phi_eff", "phi_eff_mD"), ("phi_shear", "phi_shear_mD")):
        shown = float(re.search(r"max \|phi\| ([0-9.eE+-]+) mD", figs[name]).group(1))
        assert shown == pytest.approx(acc.stats[name]["max_abs"], rel=1e-2)
        reported = np.abs(np.asarray(getattr(res, attr)))[res.valid]
        assert np.nanmax(reported) > acc.stats[name]["max_abs"]  # the guard band holds larger values


def test_figures_drawn_in_two_processes_are_those_of_one():
    """The forked second process draws the very bytes, captions and order one process draws; a child that fails
    leaves its figures to the caller."""
    import glassdist
    from glassdist.acceptance.assess import assess
    from glassdist.report import maps
    from glassdist.synthetic import synthetic_capture, wave_displacement

    cap = synthetic_capture((240, 320), pitch_mm=8.0, mm_per_px=1.0, displacement=wave_displacement(0.6, 90.0, 25.0))
    res = glassdist.analyze(cap.image, pitch_mm=8.0, distance_m=10.0, reference=cap.reference)
    acc = assess(res)
    kw = dict(limits={"phi_eff": [5.0, 10.0]}, heatmaps=True, acceptance=acc)
    one = maps.run_figures(res, cap.image, workers=1, **kw)
    two = maps.run_figures(res, cap.image, workers=2, **kw)
    assert len(one) == 9 and [f[0] for f in two] == [f[0] for f in one]
    assert two == one
    jobs = [(1.0, (lambda i=i: ("f", str(i), b"")) if i != 1 else (lambda: 1 / 0)) for i in range(4)]
    with pytest.raises(ZeroDivisionError):  # a figure that cannot be drawn fails the run, in either process
        maps.draw_figures(jobs, workers=2)


def test_quality_map_legend_names_each_label_present_with_its_share():
    from glassdist.analyzer import QUALITY_LABELS

    q = np.zeros((40, 60), np.uint8)
    q[:, :6] = 1
    q[10:20, 20:30] = 2
    q[8:22, 18:32][q[8:22, 18:32] == 0] = 6
    counts = {name: int(np.count_nonzero(q == k)) for k, name in QUALITY_LABELS.items()}
    fig, ax = figures.plot_quality(q, counts=counts)
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert [t.split(":")[0] for t in texts] == ["0", "1", "2", "6"]  # labels without pixels left out
    assert texts[1] == f"1: {QUALITY_LABELS[1]} (10.0 %)"
    # each label drawn in its own colour
    img = ax.get_images()[0]
    rgba = img.cmap(img.norm(q))
    assert len({tuple(c) for c in rgba.reshape(-1, 4)}) == 4
    figures.figure_png(fig)


def test_outputs_draw_the_quality_map_and_the_noise_floor(tmp_path):
    import json

    import glassdist
    from glassdist.synthetic import synthetic_capture, wave_displacement

    cap = synthetic_capture((200, 260), pitch_mm=8.0, mm_per_px=1.0, displacement=wave_displacement(0.4, 90.0, 20.0),
                            noise_std=0.02, rng=3)
    res = glassdist.analyze(cap.image, pitch_mm=8.0, distance_m=10.0, reference=cap.reference)
    assert glassdist.write_outputs(res, tmp_path / "o", report=True) == 0
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    sig = np.asarray(res.grid_field("phi_eff_sigma_mD"), float)
    want = np.median(sig[res.grid_valid & res.grid_trusted])
    assert s["noise_floor_mD"]["phi_eff_sigma_mD"]["median"] == pytest.approx(want, rel=1e-9) and want > 0
    assert (tmp_path / "o" / "quality.png").stat().st_size > 0 and (tmp_path / "o" / "uncertainty.png").exists()
    html = (tmp_path / "o" / "report.html").read_text()
    assert f"noise floor (median over the trusted pixels) {want:.3g} mD" in html and "Quality map" in html


@pytest.mark.slow
@needs_real_photos
@pytest.mark.parametrize("photo", ["distorted_waves.bmp", "distorted_floating_ring.bmp"])
def test_histogram_ranges_are_the_trusted_statistics_range(photo, tmp_path, monkeypatch):
    """On the real photos the histograms span exactly the largest |phi| over the trusted pixels (quality 0),
    the statistics' pixels: not the guard band's or the excluded areas' values."""
    import glassdist
    from glassdist.report import figures

    ranges = {}
    real = figures.plot_histogram

    def spy(field, valid=None, **kw):
        fig, ax = real(field, valid, **kw)
        ranges[kw["title"]] = ax.get_xlim()
        return fig, ax

    monkeypatch.setattr(figures, "plot_histogram", spy)
    res = glassdist.analyze(DATA / photo, reference=DATA / "reference.png", pitch_mm=5, distance_m=0.5,
                            detrend_degree=3)
    glassdist.write_outputs(res, tmp_path / "out", history=False)
    assert len(ranges) == 2
    for name, signed in (("phi_eff", True), ("phi_shear", False)):
        field = getattr(res, f"{name}_mD")
        top = float(np.max(np.abs(field[res.trusted & np.isfinite(field)])))  # independent of the figure code
        lo, hi = ranges[figures.CHANNEL_STYLES[name][1]]
        assert hi == pytest.approx(top, rel=1e-6) and lo == pytest.approx(-top if signed else 0.0, rel=1e-6)
        # the reported (guard band included) values reach further: the old range would have shown them
        assert np.nanmax(np.abs(np.where(res.valid, field, np.nan))) > top
