"""Figures draw only what the statistics use, on the Quick start run and the factory example run.

* no pixel outside the trusted region (quality label 0, the statistics' pixels) is drawn in a
  colour scale: in the array each map hands to matplotlib, the others are masked and drawn in
  the excluded grey, and the guard band is laid over them in its own grey; both are named in
  the legend;
* the colour limits come from the trusted pixels;
* each threshold mask's title and its drawn pixels give the Results table's share of
  report.html, to four significant figures (once: masks 23.57 / 12.08 / 10.18 % against the
  table's 12.58 / 2.988 / 1.727 %).
"""

from __future__ import annotations

import html
import json
import re
from pathlib import Path

import numpy as np
import pytest

from glassdist.report import figures as F

REPO = Path(__file__).resolve().parents[1]
REAL = REPO.parent / "shared" / "data" / "real-checkerboard-water"

pytestmark = pytest.mark.slow
EXAMPLES = REPO / "examples" / "images"

#: the runs: (photo, reference, analysis settings, specification): the README's Quick start and the factory
#: example on the project's own rendered photos, and the same two jobs on the real photographs
RUNS = {
    "quick_start": (EXAMPLES / "factory_pane.png", EXAMPLES / "factory_reference.png",
                    {"pattern": "checkerboard", "pitch_mm": 10.0, "distance_m": 1.0}, None),
    "factory": (EXAMPLES / "factory_pane.png", EXAMPLES / "factory_reference.png", {},
                REPO / "examples" / "factory" / "spec.json"),
    "real_quick_start": (REAL / "distorted_waves.bmp", REAL / "reference.png",
                         {"pattern": "checkerboard", "pitch_mm": 5.0, "distance_m": 0.5, "detrend_degree": 3}, None),
    "real_factory": (REAL / "distorted_waves.bmp", REAL / "reference.png",
                     {"pattern": "checkerboard", "pitch_mm": 5.0, "distance_m": 1.0, "detrend_degree": 2}, "real"),
}


@pytest.fixture(scope="module", params=sorted(RUNS))
def run(request, tmp_path_factory):
    """``(result, out folder, drawn)``: the run written with its report, and every map drawn, as drawn."""
    import glassdist
    from conftest import REAL_PAIR_SPEC

    image, reference, settings, spec = RUNS[request.param]
    if not image.is_file():
        pytest.skip(f"the real photographs are not in {REAL}")
    if spec == "real":
        spec = REAL_PAIR_SPEC
    elif spec is not None:  # the example's protocol pins the settings
        from glassdist.acceptance.spec import load_spec

        pr = load_spec(spec).spec.protocol
        settings = {"pattern": pr.pattern, "pitch_mm": pr.pitch_mm, "distance_m": pr.distance_m,
                    "detrend_degree": pr.detrend_degree}
    res = glassdist.analyze(image, reference=reference, **settings)
    drawn = []

    def spy(real):
        def call(*args, **kw):
            fig, ax = real(*args, **kw)
            drawn.append((real.__name__, args, kw, ax))
            return fig, ax
        return call

    out = tmp_path_factory.mktemp(request.param) / "out"
    with pytest.MonkeyPatch.context() as mp:
        # every map drawn in this process, where the spies see it (two processes draw the same bytes:
        # test_report_figures.test_figures_drawn_in_two_processes_are_those_of_one)
        mp.setenv("GLASSDIST_FIGURE_WORKERS", "1")
        for name in ("plot_channel", "plot_axis", "plot_threshold_mask"):
            mp.setattr(F, name, spy(getattr(F, name)))
        glassdist.write_outputs(res, out, report=True, spec=spec, history=False)
    return request.param, res, out, drawn


def _trusted(res):
    from glassdist.acceptance.zones import measured_region

    return measured_region(res)


def _rgba(colour):
    return np.asarray(colour, np.float32)


def test_no_pixel_outside_the_trusted_region_is_in_a_colour_scale(run):
    _, res, _, drawn = run
    trusted = _trusted(res)
    guard = np.asarray(res.valid, bool) & ~trusted
    assert guard.sum() > 0.05 * guard.size  # the guard band is large on these photos: drawn as data, it was a saturated ring
    kinds = [k for k, *_ in drawn]
    assert kinds.count("plot_channel") == 3 and kinds.count("plot_axis") == 1  # two heatmaps, the uncertainty
    for kind, args, kw, ax in drawn:
        data_image = ax.images[0] if kind != "plot_axis" else ax.images[1]
        arr = data_image.get_array()
        assert arr.shape == trusted.shape  # every pixel of the 1024 px photo
        shown = ~np.ma.getmaskarray(arr)
        assert not (shown & ~trusted).any(), kind  # nothing outside the trusted pixels in the colour scale
        if kind != "plot_axis":
            assert (shown == (trusted & np.isfinite(np.asarray(args[0])))).all()
            rgba = data_image.to_rgba(arr, bytes=False)
            np.testing.assert_allclose(rgba[~shown], np.broadcast_to(_rgba(F.EXCLUDED_RGBA), rgba[~shown].shape))
            for grey in (F.EXCLUDED_RGBA, F.GUARD_RGBA):  # no trusted pixel is drawn in the greys
                assert not np.all(np.isclose(rgba[shown], _rgba(grey), atol=0.02), axis=1).any(), kind
        # the guard band over them, in its own grey, exactly where it is
        over = ax.images[-1].get_array()
        np.testing.assert_array_equal(over[..., 3] > 0, guard)
        np.testing.assert_allclose(over[guard], np.broadcast_to(_rgba(F.GUARD_RGBA), over[guard].shape))
        legend = [t.get_text() for t in ax.figure.legends[0].get_texts()]
        assert "guard band (measured, not trusted)" in legend and "excluded / not analysed" in legend


def test_colour_limits_come_from_the_trusted_pixels(run):
    name, res, out, drawn = run
    summary = json.loads((out / "summary.json").read_text())
    heat = {kw["title"].split(",")[0]: ax for kind, args, kw, ax in drawn
            if kind == "plot_channel" and "uncertainty" not in kw["title"]}
    for channel, (attr, label, _, signed) in ((c, F.CHANNEL_STYLES[c]) for c in ("phi_eff", "phi_shear")):
        ax = heat[label]
        vmax = ax.images[0].get_clim()[1]
        assert vmax == pytest.approx(summary["colour_limits_mD"][channel])
        field = np.asarray(getattr(res, attr))
        top = np.max(np.abs(field[_trusted(res)]))
        beyond = np.nanmax(np.abs(np.where(res.valid, field, np.nan)))
        assert vmax <= top <= beyond
        if name.startswith("real"):
            assert top < beyond  # on the waves photo the guard band reaches further
        # the title's maximum is the statistics' (trusted pixels), and so is the share beyond the colour limit
        title = ax.get_title()
        assert f"max |phi| {summary['statistics'][attr]['max_abs']:.3g} mD" in title
        worst = [t.get_text() for t in ax.figure.legends[0].get_texts() if "worst regions" in t.get_text()]
        assert len(worst) == 1 and "worst_regions.csv" in worst[0]


def _table_shares(report: str) -> dict:
    """``{(channel, limit_mD): text}`` of the Results table's |phi| > T columns in report.html."""
    table = re.search(r'<table id="statistics">(.*?)</table>', report, re.DOTALL).group(1)
    rows = re.findall(r"<tr>(.*?)</tr>", table, re.DOTALL)
    head = [html.unescape(re.sub("<[^>]+>", "", c)) for c in re.findall(r"<th>(.*?)</th>", rows[0])]
    out = {}
    for row in rows[1:]:
        channel = re.search(r"<th>(.*?)</th>", row).group(1)
        cells = re.findall(r'<td class="num">(.*?)</td>', row)
        for title, cell in zip(head[1:], cells):
            m = re.match(r"\|φ\| > ([0-9.]+) mD \(% of the trusted region\)", title)
            if m and cell != "—":
                out[(channel, float(m.group(1)))] = cell
    return out


def test_every_mask_states_and_draws_the_results_table_share(run):
    name, _, out, drawn = run
    masks = [(kw, ax) for kind, args, kw, ax in drawn if kind == "plot_threshold_mask"]
    if name.endswith("quick_start"):
        assert masks == []  # no specification: no limits, no masks
        return
    report = (out / "report.html").read_text()
    table = _table_shares(report)
    assert len(masks) == len(table) == 5
    for kw, ax in masks:
        channel = next(c for c in ("phi_eff", "phi_shear") if f"|{c}|" in ax.get_title())
        want = table[(channel, kw["limit_mD"])]
        assert ax.get_title() == f"|{channel}| > {kw['limit_mD']:g} mD: {want} % of the trusted region"
        arr = ax.images[0].get_array()
        drawn_share = 100.0 * np.count_nonzero(arr == 1) / np.count_nonzero(~np.ma.getmaskarray(arr))
        assert f"{drawn_share:.4g}" == want  # the red among the coloured pixels: the same number
        caption = f"|{channel}| &gt; {kw['limit_mD']:g} mD in red, {want} % of the trusted region"
        assert caption in report
