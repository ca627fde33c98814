"""Experiment 2: grid-pitch dependence (paper §3.2, Figs. 7, 8 and 10).

A biconvex lens in a 20 mm slab is seen from a slanted viewpoint at L = 10 m
against three line grids: coarse 96.9 mm, medium 64.6 mm and fine 48.4 mm. Each
image is analysed with the Direct and the Comparative Method at N = 2 and one
metric-anchored smoothing scale ``sigma_mm`` for all three pitches, so that the
statistics describe the same physical low-pass. Reported per pitch: mean |phi_eff|
and mean |phi_shear| for both methods and for the exact landing-point truth
through the same stack, the Direct Method's spread across pitches (max deviation
from the mean of the three, relative to it) and the Direct-vs-Comparative relative
difference ``|a - b| / max(a, b)``.

Statistics are given over each run's own compared region (the paper's "displayed
valid analysis field", which shrinks for coarse grids because the border margin is
a number of carrier periods) and over the region common to all six runs, which
removes the region's share of the spread.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy import ndimage

from ._common import (
    ExperimentResult,
    RunOptions,
    SceneRun,
    bound,
    bounds_table,
    common_region,
    map_panel,
    region_stats,
    relative_difference,
    run_scenes,
    settings_record,
    share_fig_ax,
    shared_limit,
    validation_record,
)

__all__ = [
    "PAPER",
    "SCENES",
    "SIGMA_MM",
    "run_pitch",
    "pitch_inputs_figure",
    "pitch_power_figure",
    "pitch_shear_figure",
    "interior_region",
    "pitch_entry",
    "region_means",
    "pitch_summary",
    "pitch_bounds",
    "pitch_table",
]

_SCENES_DIR = Path(__file__).resolve().parents[3] / "examples" / "scenes"

#: The three scenes of §3.2, coarse to fine.
SCENES = {
    "coarse": _SCENES_DIR / "biconvex_lens_p96.yaml",
    "medium": _SCENES_DIR / "biconvex_lens_p64.yaml",
    "fine": _SCENES_DIR / "biconvex_lens_p48.yaml",
}

#: The paper's numbers (§3.2): mean |phi_eff| per pitch, mD, and the relative differences.
PAPER = {
    "direct_phi_eff_mD": {"coarse": 8.42, "medium": 8.82, "fine": 8.97},
    "comparative_phi_eff_mD": {"coarse": 7.84, "medium": 8.06, "fine": 8.51},
    "direct_spread": 0.04,
    "direct_vs_comparative": {"coarse": 0.069, "medium": 0.086, "fine": 0.051},
}

#: Bounds of issue 5: Direct spread within +-2 % of its mean, Direct vs Comparative within 3 %.
BOUNDS = {"spread": 0.02, "methods": 0.03}

#: Width of the border band left out of the interior, in smoothing scales. The compared regions
#: are the runs' trusted pixels, already a guard band of ``guard_band_sigmas`` = 1.5 sigma inside
#: each reported region: the interior lies at least 3 sigma inside every run's analysed region.
INTERIOR_SIGMAS = 1.5

DETREND_DEGREE = 2
#: One physical smoothing scale for every pitch, mm: about 1 coarse period, 2 fine periods.
SIGMA_MM = 100.0
METHODS = ("direct", "comparative")
CHANNELS = ("phi_eff", "phi_shear")


def _label(channel: str) -> str:
    return {"phi_eff": r"$\phi_{eff}$", "phi_shear": r"$\phi_{shear}$"}[channel]


def _spread(values) -> float:
    v = np.asarray(list(values), float)
    return float(np.max(np.abs(v - v.mean())) / v.mean())


def run_pitch(*, sigma_mm: float = SIGMA_MM, scenes: dict | None = None, params_file=None, **options) -> ExperimentResult:
    """Run the grid-pitch experiment.

    Parameters
    ----------
    sigma_mm : float
        Reporting smoothing scale on the backdrop, mm, shared by all pitches.
    scenes : dict, optional
        ``{'coarse' | 'medium' | 'fine': scene path}`` (default :data:`SCENES`).
    params_file : path, optional
        JSON file of analyzer parameters over each scene's own analysis settings (the
        experiment's ``sigma_mm`` and detrend degree stay over it): :func:`~glassdist.experiments._common.run_scenes`.
    **options
        ``engine``, ``scale``, ``spp``, ``progress``, ``executor``: see :class:`RunOptions`.

    Returns
    -------
    ExperimentResult
        ``record['pitches'][name][method]`` per run; ``record['summary']`` the
        means per pitch, spreads and relative differences (own and common region).

    Notes
    -----
    Spread of a method across pitches :math:`p`:
    :math:`\\max_p |m_p - \\bar m| / \\bar m` with :math:`m_p` the mean |phi| at pitch p.
    Relative difference of the methods: :math:`|a - b| / \\max(a, b)`.

    References
    ----------
    Paper §3.2, Figs. 7, 8, 10.
    """
    runs = run_scenes(
        dict(SCENES if scenes is None else scenes), RunOptions(**options),
        methods=METHODS, reference=True, detrend_degree=DETREND_DEGREE, sigma_mm=sigma_mm, params_file=params_file,
    )
    first = next(iter(runs.values()))
    common = common_region(runs)
    interior = interior_region(common, INTERIOR_SIGMAS * float(sigma_mm) / first.validations["direct"].analysis.mm_per_px)
    record: dict = {
        **settings_record(first, detrend_degree=DETREND_DEGREE, sigma_mm=sigma_mm, paper=PAPER),
        "common_region_fraction": float(common.mean()),
        "interior_region_fraction": float(interior.mean()),
        "pitches": {name: pitch_entry(run, {"common_region": common, "interior_region": interior}) for name, run in runs.items()},
    }
    record["summary"] = pitch_summary(region_means(record["pitches"]))
    record["bounds"] = pitch_bounds(record["summary"]["interior"])
    images = {n: run.inputs.distorted for n, run in runs.items()}
    figures = {
        "fig7_pitch_inputs.png": lambda: pitch_inputs_figure(images, {n: run.scene.backdrop.pitch_mm for n, run in runs.items()}),
        "fig8_pitch_phi_eff.png": lambda: pitch_power_figure(runs, channel="phi_eff"),
        "fig10_pitch_phi_shear_coarse.png": lambda: pitch_shear_figure(runs, pitch=next(iter(runs))),
    }
    return ExperimentResult("pitch", record, pitch_table(record), figures)


def interior_region(common: np.ndarray, band_px: float) -> np.ndarray:
    """The common region less a band ``band_px`` wide along its border (bool, H x W).

    There the region's edge cuts the smoothing kernel (normalised convolution)
    differently for the image and the truth; :data:`INTERIOR_SIGMAS` smoothing scales
    inside, the border convention no longer matters.
    """
    return ndimage.distance_transform_edt(np.pad(common, 1))[1:-1, 1:-1] > band_px


def pitch_entry(run: SceneRun, regions: dict) -> dict:
    """Record of one pitch: scene, settings and, per method, :func:`validation_record` plus
    the analyzer's and the truth's statistics on each of ``regions`` (key -> bool mask)."""
    entry = {**run.entry(), "pitch_mm": run.scene.backdrop.pitch_mm, "params": run.params.resolved()}
    for method in METHODS:
        val = run.validations[method]
        entry[method] = validation_record(val)
        for key, reg in regions.items():
            entry[method][key] = {
                who: {ch: region_stats(getattr(src, f"{ch}_mD"), reg) for ch in CHANNELS}
                for who, src in (("analyzer", val.analysis), ("exact", val.exact))
            }
    return entry


def region_means(pitches: dict) -> dict:
    """Mean |phi| by region (own, common, interior), who (each method, exact truth), channel and pitch, mD.

    The truth is taken on the Direct Method's region.
    """
    keys = {"own": "statistics", "common": "common_region", "interior": "interior_region"}
    means: dict = {reg: {who: {ch: {} for ch in CHANNELS} for who in (*METHODS, "exact")} for reg in keys}
    for name, entry in pitches.items():
        for reg, key in keys.items():
            for ch in CHANNELS:
                for method in METHODS:
                    means[reg][method][ch][name] = entry[method][key]["analyzer"][ch]["mean_abs"]
                means[reg]["exact"][ch][name] = entry["direct"][key]["exact"][ch]["mean_abs"]
    return means


def pitch_summary(means: dict) -> dict:
    """Per region: the means, each one's spread across pitches, Direct vs Comparative and Direct / truth."""
    summary: dict = {}
    for reg, m in means.items():
        names = list(m["direct"][CHANNELS[0]])
        s = {"mean_abs_mD": m, "spread": {}, "direct_vs_comparative": {}, "direct_vs_exact": {}}
        for ch in CHANNELS:
            s["spread"][ch] = {who: _spread(m[who][ch].values()) for who in m}
            s["direct_vs_comparative"][ch] = {
                n: relative_difference(m["direct"][ch][n], m["comparative"][ch][n]) for n in names
            }
            s["direct_vs_exact"][ch] = {n: m["direct"][ch][n] / m["exact"][ch][n] for n in names}
        summary[reg] = s
    return summary


def pitch_bounds(interior_s: dict) -> dict:
    """Bound checks on the interior: the region common to all six runs, at least 3 sigma inside their analysed regions.

    Each grid's own region differs (the image edge margin is a number of carrier
    periods), and there the exact truth itself moves by a few per cent with the
    region alone (the 'truth spread' column), which no analyzer can follow; within
    3 sigma of a border the normalised convolution's border convention weighs in.
    The own- and common-region figures stay in the tables.
    """
    bounds = {
        f"spread_direct_{ch}": bound(
            interior_s["spread"][ch]["direct"], BOUNDS["spread"], paper=PAPER["direct_spread"] if ch == "phi_eff" else None,
            what=f"Direct mean abs {ch}, interior: max deviation from its mean across pitches",
        )
        for ch in CHANNELS
    }
    for ch in CHANNELS:
        for n in interior_s["direct_vs_comparative"][ch]:
            bounds[f"direct_vs_comparative_{ch}_{n}"] = bound(
                interior_s["direct_vs_comparative"][ch][n], BOUNDS["methods"],
                paper=PAPER["direct_vs_comparative"].get(n) if ch == "phi_eff" else None,
                what=f"{ch}, {n} grid, interior: abs(D - C) / max(D, C)",
            )
    return bounds


def pitch_table(record: dict) -> str:
    """Markdown: means per pitch and method (ours, truth, paper), spreads per region, relative differences, bounds."""
    summ = record["summary"]
    own = summ["own"]
    names = list(record["pitches"])
    first = record["pitches"][names[0]]["direct"]
    lines = [
        f"Biconvex lens, slanted view, L = 10 m, {record['image_size'][0]} x {record['image_size'][1]} px, "
        f"{record['samples_per_pixel']} spp, engine {record['engine']}; N = {record['detrend_degree']}, "
        f"sigma = {record['sigma_mm']:g} mm for every pitch ({record['sigma_mm'] / first['mm_per_px']:.0f} px at "
        f"{first['mm_per_px']:.2f} mm/px). Regions: *own* = each run's compared region (the paper's displayed "
        f"field); *common* = the {100 * record['common_region_fraction']:.1f}% of the image valid in all six runs; "
        f"*interior* = the common region less a border band {INTERIOR_SIGMAS:g} sigma wide, where the bounds are judged "
        f"({100 * record['interior_region_fraction']:.1f}% of the image). Truth = exact landing points through the "
        "same stack (same N, sigma, region) as the Direct run.",
        "",
    ]
    fmt = lambda v, f="{:.2f}": "" if v is None else f.format(v)  # noqa: E731
    for ch in CHANNELS:
        eff = ch == "phi_eff"
        lines += [
            f"Mean abs {ch}, mD (own regions):",
            "",
            "| grid | pitch, mm | Direct | Comparative | abs(D-C)/max | truth | Direct / truth | paper Direct "
            "| paper Comparative | paper abs(D-C)/max |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for n in names:
            pd = PAPER["direct_phi_eff_mD"].get(n) if eff else None
            pc = PAPER["comparative_phi_eff_mD"].get(n) if eff else None
            pr = PAPER["direct_vs_comparative"].get(n) if eff else None
            lines.append(
                f"| {n} | {record['pitches'][n]['pitch_mm']:g} | {own['mean_abs_mD']['direct'][ch][n]:.3f} | "
                f"{own['mean_abs_mD']['comparative'][ch][n]:.3f} | {100 * own['direct_vs_comparative'][ch][n]:.2f}% | "
                f"{own['mean_abs_mD']['exact'][ch][n]:.3f} | {own['direct_vs_exact'][ch][n]:.4f} | {fmt(pd)} | {fmt(pc)} | "
                f"{fmt(None if pr is None else 100 * pr, '{:.1f}%')} |"
            )
        lines += [
            "",
            f"Spread of mean abs {ch} across pitches (max deviation from the mean of the three) and Direct / truth, by region"
            + (" (paper: Direct within ±4%):" if eff else ":"),
            "",
            "| region | Direct spread | Comparative spread | truth spread | "
            + " | ".join(f"Direct / truth, {n}" for n in names) + " | "
            + " | ".join(f"abs(D-C)/max, {n}" for n in names) + " |",
            "|---" * (4 + 2 * len(names)) + "|",
        ]
        for reg in ("own", "common", "interior"):
            sp = summ[reg]["spread"][ch]
            lines.append(
                f"| {reg} | {100 * sp['direct']:.2f}% | {100 * sp['comparative']:.2f}% | {100 * sp['exact']:.2f}% | "
                + " | ".join(f"{summ[reg]['direct_vs_exact'][ch][n]:.4f}" for n in names) + " | "
                + " | ".join(f"{100 * summ[reg]['direct_vs_comparative'][ch][n]:.2f}%" for n in names) + " |"
            )
        lines.append("")
    lines.append(bounds_table(record["bounds"]))
    return "\n".join(lines)


def pitch_inputs_figure(images: dict, pitches: dict, *, fig=None, ax=None):
    """Fig. 7: the rendered inputs, coarse / medium / fine.

    Parameters
    ----------
    images : dict of str -> ndarray (H, W)
        Distorted renders by grid name.
    pitches : dict of str -> float
        Grid pitch by name, mm.

    Returns
    -------
    fig, axes
    """
    fig, axes = share_fig_ax(fig, ax, nrows=1, ncols=len(images), figsize=(4.2 * len(images), 3.6))
    for a, (name, img) in zip(np.ravel(axes), images.items()):
        a.imshow(img, cmap="gray", vmin=0, vmax=1, interpolation="lanczos")
        a.set_title(f"{name} grid, pitch {pitches[name]:g} mm", fontsize=10)
        a.set_xticks([])
        a.set_yticks([])
    fig.tight_layout()
    return fig, axes


def pitch_power_figure(runs: dict, *, channel: str = "phi_eff", fig=None, ax=None):
    """Fig. 8: phi per pitch (rows): Comparative, Direct and the exact truth (columns), one colour scale.

    Titles give the mean |phi| and the standard deviation of signed phi over each
    panel's region (the run's compared region).

    Returns
    -------
    fig, axes
    """
    key = f"{channel}_mD"
    names = list(runs)
    panels = []
    for n in names:
        c, d = runs[n].validations["comparative"], runs[n].validations["direct"]
        panels.append(
            [(getattr(c.analysis, key), c.valid, "Comparative"), (getattr(d.analysis, key), d.valid, "Direct"),
             (getattr(d.exact, key), d.valid, "exact truth")]
        )
    flat = [p for row in panels for p in row]
    lim = shared_limit([p[0] for p in flat], [p[1] for p in flat])
    signed = channel == "phi_eff"
    fig, axes = share_fig_ax(fig, ax, nrows=len(names), ncols=3, figsize=(14, 3.4 * len(names)))
    for i, n in enumerate(names):
        pitch = runs[n].scene.backdrop.pitch_mm
        for j, (m, reg, who) in enumerate(panels[i]):
            st = region_stats(m, reg)
            map_panel(
                axes[i, j], fig, m, reg, vmin=-lim if signed else 0.0, vmax=lim, cmap="RdBu_r" if signed else "viridis",
                title=f"{who}, {n} grid ({pitch:g} mm)\n"
                      f"{_label(channel)}: mean abs {st['mean_abs']:.3f} mD, std {st['std']:.3f} mD",
            )
    fig.tight_layout()
    return fig, axes


def pitch_shear_figure(runs: dict, *, pitch: str = "coarse", fig=None, ax=None):
    """Fig. 10: phi_shear on one grid, Comparative vs Direct (and the exact truth), one colour scale.

    Returns
    -------
    fig, axes
    """
    run = runs[pitch]
    c, d = run.validations["comparative"], run.validations["direct"]
    panels = [(c.analysis.phi_shear_mD, c.valid, "Comparative"), (d.analysis.phi_shear_mD, d.valid, "Direct"),
              (d.exact.phi_shear_mD, d.valid, "exact truth")]
    lim = shared_limit([p[0] for p in panels], [p[1] for p in panels])
    fig, axes = share_fig_ax(fig, ax, nrows=1, ncols=3, figsize=(14, 3.6))
    p_mm = run.scene.backdrop.pitch_mm
    for a, (m, reg, who) in zip(np.ravel(axes), panels):
        st = region_stats(m, reg)
        map_panel(
            a, fig, m, reg, vmin=0.0, vmax=lim, cmap="viridis",
            title=f"{who}, {pitch} grid ({p_mm:g} mm)\n"
                  f"{_label('phi_shear')}: mean abs {st['mean_abs']:.3f} mD, std {st['std']:.3f} mD",
        )
    fig.tight_layout()
    return fig, axes
