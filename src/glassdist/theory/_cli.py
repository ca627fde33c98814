"""``glassdist predict``: the analytical model's displacement and channels on the camera pixel grid."""

from __future__ import annotations

import json

import numpy as np

from .._cli_shared import add_analysis_options, add_scene_command
from .._version import __version__
from ..io import prepare_output_dir
from ..scene import load_scene

__all__ = ["register", "run"]


def register(subparsers):
    """Add the ``predict`` sub-command."""
    p = add_scene_command(
        subparsers, "predict", run,
        help="analytical model: displacement and power channels on the camera pixel grid",
        description="Evaluate the Optical Theoretical Model (first-order Snell forward model) for every "
        "camera pixel and pass it through the evaluation stack (detrend, smoothing, channels). Writes "
        "prediction.npz (displacement_mm, displacement_detrended_mm, phi_eff_mD, phi_shear_mD, "
        "phi_total_mD, axis_deg, valid, incidence_deg, the additive terms) and prediction.json.",
    )
    add_analysis_options(p)
    return p


def run(args) -> int:
    from ..analyzer.metrics import channel_statistics
    from . import analysis_params, carrier_period_mm, nominal_mm_per_px, predict_channels, reflection_geometry

    scene = load_scene(args.scene)
    params = analysis_params(scene, args.params, sigma_mm=args.sigma_mm, detrend_degree=args.detrend_degree)
    sigma = params.sigma_mm if params.sigma_mm is not None else params.sigma_periods * carrier_period_mm(scene)
    if params.sigma_mm is None and scene.reflection:  # the periods of the board's image, as a length on the pane
        sigma /= reflection_geometry(scene).magnification
    mpp = nominal_mm_per_px(scene)
    pred, ch, valid = predict_channels(
        scene, sigma_mm=sigma, detrend_degree=params.detrend_degree, mm_per_px=mpp,
        projective=params.a1_mode == "projective",
    )
    out = prepare_output_dir(args.out)
    arrays = {
        "displacement_mm": pred.displacement_mm,
        "displacement_detrended_mm": ch.displacement_detrended_mm,
        "phi_eff_mD": ch.phi_eff_mD,
        "phi_shear_mD": ch.phi_shear_mD,
        "phi_total_mD": ch.phi_total_mD,
        "axis_deg": ch.axis_deg,
        "valid": valid,
        "status": pred.status,
        "incidence_deg": pred.incidence_deg,
        **{f"term_{k}_mm": v for k, v in pred.terms_mm.items()},
    }
    np.savez_compressed(out / "prediction.npz",
                        **{k: np.asarray(v, np.float32) if v.dtype.kind == "f" else v for k, v in arrays.items()})
    stats = {n: channel_statistics(getattr(ch, n), valid) for n in ("phi_eff_mD", "phi_shear_mD", "phi_total_mD")}
    record = {
        "glassdist_version": __version__,
        "scene": scene.name,
        "mm_per_px": mpp,
        "sigma_mm": sigma,
        "detrend_degree": params.detrend_degree,
        "a1_mode": params.a1_mode,
        "incidence_deg": [float(pred.incidence_deg.min()), float(pred.incidence_deg.max())],
        "max_abs_displacement_mm": float(np.nanmax(np.abs(pred.displacement_mm))),
        "statistics": stats,
    }
    (out / "prediction.json").write_text(json.dumps(record, indent=2), encoding="utf-8")
    print(f"analytical model: mean |phi_eff| {stats['phi_eff_mD']['mean_abs']:.3g} mD, "
          f"mean phi_shear {stats['phi_shear_mD']['mean_abs']:.3g} mD (sigma {sigma:.3g} mm, "
          f"detrend {params.detrend_degree}); written to {out}")
    return 0
