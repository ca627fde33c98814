"""The lines a run prints, from its record (rendering only: nothing is read back from the run's files).

:func:`warning_lines` go to stderr (even with ``--quiet``), :func:`run_lines` to stdout:
the verdict and one line per check, one line per zone, the report's path, the statistics
of the run, what was removed of an earlier run and where the results are.
"""

from __future__ import annotations

__all__ = ["acceptance_lines", "run_lines", "warning_lines"]


def acceptance_lines(acc, report_path=None) -> list[str]:
    """The verdict (one line per check), one line per zone and the report's path."""
    lines = list(acc.verdict.lines()) if acc.verdict is not None else []
    for name, z in acc.zones.items():
        eff, shear = z["statistics"].get("phi_eff", {}), z["statistics"].get("phi_shear", {})
        share = z["trusted_percent"]
        if share is None or share != share:  # NaN: the zone has no pixel in the photo
            lines.append(f"zone {name}: not in the photo, nothing of it judged")
            continue
        lines.append(f"zone {name}: trusted {share:.4g} % of the zone, p95 |phi_eff| "
                     f"{_mD(eff.get('p95_abs'))}, p95 |phi_shear| {_mD(shear.get('p95_abs'))}")
    if report_path is not None:
        lines.append(f"report: {report_path}")
    return lines


def _mD(v) -> str:
    """A statistic for a console line: ``n/a`` where no pixel was trusted (None or NaN)."""
    return "n/a" if v is None or v != v else f"{v:.4g} mD"


def warning_lines(record, problems=()) -> list[str]:
    """``warning: ...`` lines: the acceptance's, the analysis's, and files of an earlier run that could not be removed."""
    return [f"warning: {w}" for w in (*record.acceptance.warnings, *record.result.warnings, *problems)]


def run_lines(record, summary, out_dir, removed=()) -> list[str]:
    """The stdout lines of ``glassdist analyze`` for a run written into ``out_dir`` (``summary``: what it wrote)."""
    result = record.result
    lines = acceptance_lines(record.acceptance, out_dir / "report.html" if record.request.report else None)
    s = summary["statistics"]
    optics = "" if result.optics is None else (
        f"reflection (D {result.optics.board_distance_m:g} m, incidence {result.optics.incidence_deg:g} deg), ")

    def mD(v) -> str:  # null when no pixel is trusted
        return "n/a" if v is None else f"{v:.3g} mD"

    lines.append(
        f"{optics}{result.method} method: measured {summary['measured_percent']:.4g} %, "
        f"trusted {summary['trusted_percent']:.4g} % of {'the mask' if record.request.mask is not None else 'the image'}, "
        f"mean |phi_eff| {mD(s['phi_eff_mD']['mean_abs'])}, p95 |phi_eff| {mD(s['phi_eff_mD']['p95_abs'])}, "
        f"mean phi_shear {mD(s['phi_shear_mD']['mean_abs'])}"
    )
    if removed:
        lines.append(f"removed from {out_dir}, left by the previous run: {', '.join(removed)}")
    lines.append(f"results written to {out_dir}")
    return lines
