"""The lines a run prints: verdict, zones and the report's path (rendering only)."""

from __future__ import annotations

import sys

__all__ = ["echo_acceptance"]


def echo_acceptance(acc, report_path, echo):
    """The user-facing lines of an acceptance: warnings (stderr), verdict, zones, the report's path."""
    for w in acc.warnings:
        print(f"warning: {w}", file=sys.stderr)
    if acc.verdict is not None:
        for line in acc.verdict.lines():
            echo(line)
    for name, z in acc.zones.items():
        eff, shear = z["statistics"].get("phi_eff", {}), z["statistics"].get("phi_shear", {})
        echo(f"zone {name}: {z['coverage_percent']:.1f} % analysed, p95 |phi_eff| {eff.get('p95_abs', float('nan')):.4g} mD, "
             f"p95 |phi_shear| {shear.get('p95_abs', float('nan')):.4g} mD")
    if report_path is not None:
        echo(f"report: {report_path}")
