"""``glassdist validate``: both branches of the Virtual Pipeline on one scene, compared (Table 2, Fig. 6)."""

from __future__ import annotations

import json

import numpy as np

from .._cli_shared import add_analysis_options, add_render_options, add_scene_command, apply_render_overrides, progress_reporter
from ..io import prepare_output_dir, write_png16
from ..scene import load_scene

__all__ = ["register", "run"]


def register(subparsers):
    """Add the ``validate`` sub-command."""
    p = add_scene_command(
        subparsers, "validate", run,
        help="render + analyse a scene and compare with the analytical model (validation.json, validation.png)",
        description="Run both branches of the Virtual Pipeline: render the scene and analyse the image "
        "(Direct or Comparative Method), evaluate the analytical model, pass it through the same "
        "evaluation stack and write DIR/validation.json (magnitude ratios Analyzer/analytical, map "
        "correlations, Procrustes rotation and scale), validation.png, distorted.png and reference.png.",
    )
    p.add_argument("--method", choices=["direct", "comparative"], default="direct", help="analyzer method (default direct)")
    add_analysis_options(p)
    add_render_options(p)
    return p


def run(args) -> int:
    from ..theory import analysis_params
    from . import validate_scene, validation_figure

    scene = apply_render_overrides(load_scene(args.scene), args)
    params = analysis_params(scene, args.params, sigma_mm=args.sigma_mm, detrend_degree=args.detrend_degree)
    out = prepare_output_dir(args.out)
    with progress_reporter(not args.no_progress) as report:
        val, record = validate_scene(scene, method=args.method, engine=args.engine, params=params, progress=report)
    distorted, reference = record.pop("_distorted"), record.pop("_reference")
    write_png16(out / "distorted.png", distorted)
    write_png16(out / "reference.png", reference)
    (out / "validation.json").write_text(json.dumps(record, indent=2), encoding="utf-8")
    fig, _ = validation_figure(val, distorted, reference)
    fig.savefig(out / "validation.png", dpi=110)
    import matplotlib.pyplot as plt

    plt.close(fig)
    np.savez_compressed(
        out / "validation_fields.npz",
        valid=val.valid,
        **{f"{who}_{n}": np.asarray(getattr(fields, n), np.float32)
           for who, fields in (("analyzer", val.analysis), ("analytical", val.analytical))
           for n in ("phi_eff_mD", "phi_shear_mD", "phi_total_mD", "displacement_detrended_mm")},
    )
    r, pr = record["ratios"], record["procrustes"]
    print(
        f"{record['method']} method vs analytical model: ratios phi_eff {r['phi_eff']:.4f}, phi_shear "
        f"{r['phi_shear']:.4f}, phi_total {r['phi_total']:.4f}; Procrustes rotation {pr['rotation_deg']:+.4f} deg, "
        f"scale {pr['scale']:.4f}; written to {out}"
    )
    for w in record["analyzer"]["warnings"]:
        print(f"warning: {w}")
    return 0
