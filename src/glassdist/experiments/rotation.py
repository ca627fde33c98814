"""Experiment 3: stability under in-plane rotation of the grid (paper §3.3, Fig. 9).

The same mildly distorted slab (weak roller wave plus two localised back-face
defects), the same near-orthographic camera at L = 10 m and the fine 48.4 mm line
grid, once axis-aligned and once rotated about its own normal (20 deg in the
shipped scenes). Both images are analysed with the Direct Method at N = 2 and one
``sigma_mm``; the glass and the camera do not move, so the camera-frame phi_eff
maps should coincide. Reported: mean |phi_eff| of each and their ratio min/max,
over each run's own region and over the common region, and each run against the
exact landing-point truth through the same stack.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._common import (
    ExperimentResult,
    RunOptions,
    SceneRun,
    bound,
    bounds_table,
    common_region,
    map_panel,
    region_stats,
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
    "run_rotation",
    "rotation_figure",
    "rotation_entry",
    "rotation_summary",
    "rotation_table",
]

_SCENES_DIR = Path(__file__).resolve().parents[3] / "examples" / "scenes"

#: The two scenes of §3.3.
SCENES = {"aligned": _SCENES_DIR / "mild_slab_aligned.yaml", "rotated": _SCENES_DIR / "mild_slab_rotated.yaml"}

#: The paper's numbers (§3.3, Fig. 9): mean |phi_eff|, mD, and the ratio min/max.
PAPER = {"aligned_phi_eff_mD": 1.06, "rotated_phi_eff_mD": 1.01, "ratio": 0.952}

#: Bound of issue 5: the ratio within 2 % of 1.
BOUNDS = {"ratio": 0.02}

DETREND_DEGREE = 2
#: Reporting smoothing scale on the backdrop, mm (2 periods of the 48.4 mm grid, rounded).
SIGMA_MM = 100.0


def run_rotation(*, sigma_mm: float = SIGMA_MM, scenes: dict | None = None, params_file=None, **options) -> ExperimentResult:
    """Run the grid-rotation experiment.

    Parameters
    ----------
    sigma_mm : float
        Reporting smoothing scale on the backdrop, mm.
    scenes : dict, optional
        ``{'aligned': path, 'rotated': path}`` (default :data:`SCENES`).
    params_file : path, optional
        JSON file of analyzer parameters over each scene's own analysis settings (the
        experiment's ``sigma_mm`` and detrend degree stay over it): :func:`~glassdist.experiments._common.run_scenes`.
    **options
        ``engine``, ``scale``, ``spp``, ``progress``, ``executor``: see :class:`RunOptions`.

    Returns
    -------
    ExperimentResult
        ``record['ratio']`` = min/max of the two mean |phi_eff| (own regions, as the
        paper); ``record['ratio_common']`` on the common region.

    References
    ----------
    Paper §3.3, Fig. 9.
    """
    paths = dict(SCENES if scenes is None else scenes)
    if set(paths) != {"aligned", "rotated"}:
        raise ValueError("scenes must map 'aligned' and 'rotated' to scene files")
    runs = run_scenes(
        paths, RunOptions(**options), methods=("direct",), reference=False, detrend_degree=DETREND_DEGREE, sigma_mm=sigma_mm,
        params_file=params_file,
    )
    common = common_region(runs)
    record: dict = {
        **settings_record(runs["aligned"], detrend_degree=DETREND_DEGREE, sigma_mm=sigma_mm, paper=PAPER),
        "common_region_fraction": float(common.mean()),
        "runs": {name: rotation_entry(run, common) for name, run in runs.items()},
    }
    record.update(rotation_summary(record["runs"], runs, common))
    record["bounds"] = {
        "ratio": bound(record["ratio"], BOUNDS["ratio"], target=1.0, paper=PAPER["ratio"], what="mean abs phi_eff ratio min/max"),
    }
    figures = {"fig9_rotation.png": lambda: rotation_figure(runs, record)}
    return ExperimentResult("rotation", record, rotation_table(record), figures)


def rotation_entry(run: SceneRun, common: np.ndarray) -> dict:
    """Record of one grid orientation: :func:`validation_record` of its Direct run, the scene's
    settings and the analyzer's and the truth's phi_eff statistics on the ``common`` region."""
    val = run.validations["direct"]
    return {
        **validation_record(val),
        **run.entry(),
        "grid_rotation_deg": run.scene.backdrop.rotation_deg,
        "common_region": {
            "analyzer": region_stats(val.analysis.phi_eff_mD, common),
            "exact": region_stats(val.exact.phi_eff_mD, common),
        },
    }


def rotation_summary(entries: dict, runs: dict, common: np.ndarray) -> dict:
    """Mean |phi_eff| per orientation, the ratios min/max (own region, common region, truth) and the
    agreement of the two phi_eff maps on the common region (rms difference, correlation)."""

    def ratio(means: dict) -> float:
        return min(means.values()) / max(means.values())

    own = {n: e["statistics"]["analyzer"]["phi_eff"]["mean_abs"] for n, e in entries.items()}
    a, r = (runs[n].validations["direct"].analysis.phi_eff_mD for n in ("aligned", "rotated"))
    d = (a - r)[common]
    return {
        "mean_abs_phi_eff_mD": own,
        "ratio": ratio(own),
        "relative_difference": 1.0 - ratio(own),
        "ratio_common": ratio({n: e["common_region"]["analyzer"]["mean_abs"] for n, e in entries.items()}),
        "ratio_exact": ratio({n: e["statistics"]["exact"]["phi_eff"]["mean_abs"] for n, e in entries.items()}),
        "map_difference_rms_mD": float(np.sqrt(np.mean(d * d))),
        "map_correlation": float(np.corrcoef(a[common], r[common])[0, 1]),
    }


def rotation_table(record: dict) -> str:
    """Markdown: mean |phi_eff| aligned vs rotated (ours, truth, paper), ratios, bound."""
    al, ro = record["runs"]["aligned"], record["runs"]["rotated"]
    lines = [
        f"Mild slab, near-orthographic view, L = 10 m, fine 48.4 mm grid, {record['image_size'][0]} x "
        f"{record['image_size'][1]} px, {record['samples_per_pixel']} spp, engine {record['engine']}; Direct Method, "
        f"N = {record['detrend_degree']}, sigma = {record['sigma_mm']:g} mm ({record['sigma_mm'] / al['mm_per_px']:.0f} px).",
        "",
        "| grid | rotation, deg | mean abs phi_eff, mD | std, mD | exact truth, mD | Analyzer / truth "
        "| common region, mD | paper, mD |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, e, p in (("aligned", al, PAPER["aligned_phi_eff_mD"]), ("rotated", ro, PAPER["rotated_phi_eff_mD"])):
        st = e["statistics"]
        lines.append(
            f"| {name} | {e['grid_rotation_deg']:g} | {st['analyzer']['phi_eff']['mean_abs']:.4f} | "
            f"{st['analyzer']['phi_eff']['std']:.4f} | {st['exact']['phi_eff']['mean_abs']:.4f} | "
            f"{e['ratios_vs_exact']['phi_eff']:.4f} | {e['common_region']['analyzer']['mean_abs']:.4f} | {p:.2f} |"
        )
    lines += [
        "",
        f"Ratio min/max of mean |phi_eff|: **{record['ratio']:.4f}** (relative difference "
        f"{100 * record['relative_difference']:.2f}%; paper 0.952, 4.8%); on the common region "
        f"{record['ratio_common']:.4f}; exact truth {record['ratio_exact']:.4f}. Maps: correlation "
        f"{record['map_correlation']:.4f}, rms difference {record['map_difference_rms_mD']:.4f} mD.",
        "",
        bounds_table(record["bounds"]),
    ]
    return "\n".join(lines)


def rotation_figure(runs: dict, record: dict, *, fig=None, ax=None):
    """Fig. 9: Direct-Method phi_eff, grid aligned (top) and rotated (bottom), next to the exact truth.

    One colour scale for the four panels; titles give the mean |phi_eff| and the
    standard deviation of signed phi_eff; the ratio is annotated below.

    Returns
    -------
    fig, axes
    """
    panels = []
    for name in ("aligned", "rotated"):
        v = runs[name].validations["direct"]
        rot = runs[name].scene.backdrop.rotation_deg
        panels.append([(v.analysis.phi_eff_mD, v.valid, f"Direct, grid {name} ({rot:g} deg)"),
                       (v.exact.phi_eff_mD, v.valid, f"exact truth, grid {name}")])
    flat = [p for row in panels for p in row]
    lim = shared_limit([p[0] for p in flat], [p[1] for p in flat])
    fig, axes = share_fig_ax(fig, ax, nrows=2, ncols=2, figsize=(11, 8))
    for i, row in enumerate(panels):
        for j, (m, reg, who) in enumerate(row):
            st = region_stats(m, reg)
            map_panel(axes[i, j], fig, m, reg, vmin=-lim, vmax=lim, cmap="RdBu_r",
                      title=f"{who}\n$\\phi_{{eff}}$: mean abs {st['mean_abs']:.3f} mD, std {st['std']:.3f} mD")
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    fig.text(
        0.5, 0.015,
        f"mean |phi_eff| ratio (min/max) = {record['ratio']:.4f}, relative difference = "
        f"{100 * record['relative_difference']:.2f}% (paper 0.952, 4.8%)",
        ha="center", fontsize=11,
    )
    return fig, axes
