"""``glassdist view`` and ``glassdist compare``: a capture seen from elsewhere; two captures of one pane."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ._cli_shared import folder_option
from .validation import DISTANCE_M, SIGMA_MM, number_option

__all__ = ["add_capture_options", "check_capture_options", "register", "with_capture_pose"]


def add_capture_options(p) -> None:
    """``analyze``'s ``--camera-angle-deg`` and ``--camera-azimuth-deg`` (the oblique capture's pose)."""
    p.add_argument("--camera-angle-deg", type=float,
                   help="transmission, with --camera-distance-m: angle between the camera's line of sight to the pane "
                   "centre and the pane normal, deg (0 to 70; default: from the Direct homography where it tells, "
                   "else 0)")
    p.add_argument("--camera-azimuth-deg", type=float,
                   help="with --camera-angle-deg: 0 the camera on the pane's -x side (image left) looking towards +x, "
                   "90 on its -y side (image top) looking towards +y, deg (default 0)")


def check_capture_options(args, optics) -> None:
    """The capture-pose options against each other (InputError, one line)."""
    import math

    from .errors import InputError
    from .viewpoint.view import MAX_VIEWING_ANGLE_DEG

    theta, psi = args.camera_angle_deg, args.camera_azimuth_deg
    if theta is None and psi is None:
        return
    if args.camera_distance_m is None or optics is not None:
        raise InputError("--camera-angle-deg and --camera-azimuth-deg state a transmission capture's pose: add "
                         "--camera-distance-m Dc (and leave out --optics reflection; a reflection run takes "
                         "--incidence-deg)")
    if theta is None:
        raise InputError("--camera-azimuth-deg needs --camera-angle-deg (the angle to the pane normal)")
    if not (math.isfinite(theta) and 0.0 <= theta < MAX_VIEWING_ANGLE_DEG):
        raise InputError(f"--camera-angle-deg {theta:g} is outside [0, {MAX_VIEWING_ANGLE_DEG:g}); give the angle "
                         "between the line of sight to the pane centre and the pane normal, deg")
    if psi is not None and not math.isfinite(psi):
        raise InputError(f"--camera-azimuth-deg must be a number of degrees, got {psi!r}")


def with_capture_pose(request, result, args, camera, lens):
    """``(request, result)`` with the capture's pose (stated, else estimated) and its warnings."""
    from dataclasses import replace

    if request.camera_distance_m is None or result.optics is not None:
        return request, result
    from .viewpoint.pose import capture_pose

    pose = capture_pose(result, request.camera_distance_m, angle_deg=args.camera_angle_deg,
                        azimuth_deg=args.camera_azimuth_deg or 0.0,
                        focal_length_px=getattr(lens, "focal_px", None), camera=camera)
    warnings = list(pose.warnings)
    spec = getattr(request.spec, "spec", None)
    if pose.geometry.viewing_angle_deg > 0 and getattr(spec, "reference_geometry", None) is not None:
        warnings.append(f"the specification's reference_geometry factor is that of a capture at normal incidence; this "
                        f"capture is {pose.geometry.viewing_angle_deg:.3g} deg off the normal, which the factor leaves "
                        "out: 'glassdist view' predicts the reading at the specification's geometry in full")
    if warnings:
        result = replace(result, warnings=(*result.warnings, *warnings))
    return replace(request, capture_pose=pose), result


def register(subparsers):
    """Add the ``view`` and ``compare`` sub-commands."""
    p = subparsers.add_parser(
        "view", help="predict what analyze would report on a photo of the pane taken from another point",
        description="From a result analysed with --camera-distance-m, predict the statistics and maps analyze would "
        "report on a photo from an observer Do from the pane centre with the backdrop Lo behind it, aimed at the pane "
        "centre, along a line of sight at --viewing-angle-deg to the pane normal. Writes summary.json (with the "
        "photo's camera) and result.npz (on the photo's pixel grid) to --out.")
    p.add_argument("result", type=Path, help="output folder of a 'glassdist analyze' run with --camera-distance-m")
    p.add_argument("--observer-distance-m", type=number_option(DISTANCE_M), required=True,
                   help="observer (camera) to the pane centre along the line of sight, Do, m")
    p.add_argument("--background-distance-m", type=number_option(DISTANCE_M), required=True,
                   help="pane to the backdrop seen through it, Lo, m")
    p.add_argument("--viewing-angle-deg", type=float, default=0.0,
                   help="angle between the line of sight to the pane centre and the pane normal, deg (0 to 70; default 0)")
    p.add_argument("--viewing-azimuth-deg", type=float, default=0.0,
                   help="0: the observer on the capture's -x side (image left) looking towards +x, 90: on its -y side "
                   "(image top) looking towards +y, deg")
    p.add_argument("--sigma-mm", type=number_option(SIGMA_MM),
                   help="the photo's smoothing on its backdrop, mm (default and least: the capture's carried there)")
    p.add_argument("--detrend-degree", type=int, help="A2 detrend degree of the photo (default the capture's)")
    p.add_argument("--out", type=folder_option, required=True, metavar="DIR", help="output folder")
    p.set_defaults(func=_run_view)

    q = subparsers.add_parser(
        "compare", help="two captures of one pane on the intrinsic axis: their difference and its uncertainty",
        description="Both results analysed with --camera-distance-m (oblique: with the angle stated or estimated), "
        "aimed at the pane centre. "
        "Prints the intrinsic mean absolute phi_eff and mean phi_shear of each over the pane area both trust, their "
        "difference with its expanded uncertainty (k = 2), and whether it is consistent with zero.")
    q.add_argument("result_a", type=Path, help="output folder of the first capture")
    q.add_argument("result_b", type=Path, help="output folder of the second capture")
    q.add_argument("--json", type=Path, metavar="FILE", help="also write the comparison as JSON")
    q.set_defaults(func=_run_compare)
    return p


def _same_folder(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve()
    except OSError:
        return False


def _run_view(args) -> int:
    from .errors import InputError
    from .fs import atomic_write, atomic_write_text
    from .io import prepare_output_dir, to_jsonable
    from .storage import load_result
    from .storage.fields import write_npz
    from .viewpoint.view import predict_view

    if _same_folder(args.out, args.result):
        raise InputError(f"--out '{args.out}' is the result folder itself; give another folder (inputs are never "
                         "overwritten)")
    stored = load_result(args.result)
    pred = predict_view(stored, observer_distance_m=args.observer_distance_m,
                        background_distance_m=args.background_distance_m, viewing_angle_deg=args.viewing_angle_deg,
                        viewing_azimuth_deg=args.viewing_azimuth_deg, sigma_mm=args.sigma_mm,
                        detrend_degree=args.detrend_degree)
    out = prepare_output_dir(args.out)
    members = [(k, np.asarray(getattr(pred, k), np.float32), False) for k in
               ("displacement_detrended_mm", "phi_eff_mD", "phi_shear_mD", "phi_total_mD", "axis_deg")]
    members += [("valid", np.asarray(pred.valid, bool), True), ("trusted", np.asarray(pred.trusted, bool), True)]
    atomic_write(out / "result.npz", lambda fh: write_npz(fh, members))
    summary = {**pred.summary(), "source": str(args.result)}
    atomic_write_text(out / "summary.json", json.dumps(to_jsonable(summary), indent=2, allow_nan=False) + "\n")
    import sys

    for w in pred.warnings:
        print(f"glassdist: warning: {w}", file=sys.stderr)
    st = pred.statistics
    print(f"view from {pred.observer.camera_distance_m:g} m at {pred.viewing_angle_deg:g} deg (azimuth "
          f"{pred.viewing_azimuth_deg:g} deg), backdrop {pred.observer.distance_m:g} m behind: "
          f"mean |phi_eff| {st['phi_eff_mD']['mean_abs']:.4g} mD, mean phi_shear {st['phi_shear_mD']['mean_abs']:.4g} mD "
          f"(sigma {pred.sigma_mm:.4g} mm, detrend {pred.detrend_degree}); written to {out}")
    return 0


def _run_compare(args) -> int:
    from .fs import atomic_write_text
    from .io import to_jsonable
    from .storage import load_result
    from .viewpoint.compare import compare_results

    cmp = compare_results(load_result(args.result_a), load_result(args.result_b))
    import sys

    for w in cmp.warnings:
        print(f"glassdist: warning: {w}", file=sys.stderr)
    for label, d in (("mean |phi_eff|", cmp.phi_eff_mean_abs), ("mean phi_shear", cmp.phi_shear_mean)):
        verdict = "consistent with zero" if d.consistent else "a difference"
        print(f"intrinsic {label}: A {d.a:.4g} mD, B {d.b:.4g} mD, A - B {d.difference:+.3g} +- {d.expanded_uncertainty:.2g} "
              f"mD (k = 2): {verdict}")
    if args.json is not None:
        atomic_write_text(args.json, json.dumps(to_jsonable(cmp.to_dict()), indent=2, allow_nan=False) + "\n")
    return 0
