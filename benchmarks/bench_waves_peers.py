"""glassdist against two independent peers on the bundled waves photo (Comparative Method).

Peers, each given the reference and the distorted photo:

* FCD, a compact fast checkerboard demodulation (``benchmarks/_fcd.py``, Wildeman 2018);
* OpenCV Farneback optical flow without a pyramid (``levels=1``: the photo's own scale only;
  a pyramid locks onto the wrong period of a checkerboard), computed from the photo to the
  reference so that it is defined at the photo's pixels (``benchmarks/_flow.py``), at the
  setting ``FARNEBACK`` (the largest agreement with FCD over ``--farneback-sweep``).

Every field is written as ``u`` (px) with ``img(r) = ref(r - u(r))`` (glassdist:
``u = -displacement_mm / mm_per_px``). Scores:

* **explains the photo**: the reference warped by the field, ``ref(r - u(r))``
  (``cv2.remap``), correlated (Pearson) with the distorted photo over glassdist's
  valid region (the same pixels for every method), and over the part of it more than one
  carrier period from its border;
* **amplitude**: regression slope of glassdist's field on FCD's at matched smoothing (the
  peer's field passed through the documented transfer of glassdist's displacement output:
  Block F's Gaussian per carrier or, after F5, ``(1 - (1 - G B)^n) / B``, times the analysis
  grid's block means and the interpolation to the pixels; then every field
  restricted to glassdist's region and smoothed by one carrier period over it, NaN-aware),
  means removed, over the pixels where both are valid; 1 = the same amplitude. Every score is
  also given for the peers at matched smoothing ("matched");
* **border bands**: the correlation by distance from the border of glassdist's region and by the
  quality label of what lies beyond that border (``border_bands``);
* **scale the photo prefers**: the factor on each field's deviations from its mean whose warped
  reference explains the photo best (``best_scale``): the photo's own verdict on the amplitude,
  with no transfer model and no peer (a field attenuated by ``a`` reads about ``1 / a``);
* **agreement area**: every pixel where FCD and Farneback agree within 0.1 carrier period;
  **coverage** = share of it inside glassdist's ``valid``;
  **inside** = share of glassdist's ``valid`` within it; **accuracy** = share of
  ``valid`` where glassdist agrees with FCD within 0.1 period.

Usage::

    python benchmarks/bench_waves_peers.py [--params JSON] [--image PATH] [--out FILE.md]
    python benchmarks/bench_waves_peers.py --farneback-sweep [--out FILE.md]
    python benchmarks/bench_waves_peers.py --replica [--out FILE.md]

``--out docs/records/waves_peers.md`` is the table the docs show (the command is written in it).
``--replica`` asks which of glassdist and FCD is right where the photo alone cannot say: it
builds replicas of the photo with a known displacement (``replicas``) and scores every method
against that truth (docs/records/waves_replica.md).
``--farneback-sweep`` runs the Farneback peer over a grid of its own settings (window, iterations,
polynomial expansion) and tabulates, per setting, the area where the two peers agree and the share
of glassdist's region inside it. A setting is judged by the peers' agreement alone, which does not
involve glassdist (docs/records/waves_peers_farneback.md).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from _fcd import fcd_displacement  # noqa: E402
from _flow import farneback_displacement  # noqa: E402
from _record import write_record  # noqa: E402

TOL_PERIODS = 0.1
# The photos' nominal glass-to-grid distance (their source records none; the README's Quick start)
DISTANCE_M = 0.5
# The Farneback peer's setting: the largest agreement with FCD over --farneback-sweep (a choice
# that involves the peers alone, not glassdist).
FARNEBACK = {"winsize": 15, "iterations": 30, "poly_n": 7, "poly_sigma": 1.5}


def warp_reference(ref: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``ref(r - u(r))`` by bilinear interpolation; NaN where u is NaN."""
    import cv2

    H, W = ref.shape
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    uu = np.nan_to_num(u).astype(np.float32)
    out = cv2.remap(ref.astype(np.float32), xx - uu[..., 0], yy - uu[..., 1], cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REFLECT)
    out[~np.all(np.isfinite(u), axis=-1)] = np.nan
    return out


def correlation(a: np.ndarray, b: np.ndarray, where: np.ndarray) -> float:
    sel = where & np.isfinite(a) & np.isfinite(b)
    return float(np.corrcoef(a[sel], b[sel])[0, 1])


def smooth_nan(u: np.ndarray, sigma_px: float) -> np.ndarray:
    """Gaussian smoothing of each component over its finite samples (normalised convolution)."""
    from scipy import ndimage

    ok = np.all(np.isfinite(u), axis=-1)
    w = ndimage.gaussian_filter(ok.astype(float), sigma_px)
    out = np.stack([ndimage.gaussian_filter(np.where(ok, u[..., c], 0.0), sigma_px) for c in range(2)], -1)
    with np.errstate(invalid="ignore", divide="ignore"):
        out /= w[..., None]
    out[~ok] = np.nan
    return out


def slope(a: np.ndarray, b: np.ndarray, where: np.ndarray) -> float:
    """Least-squares slope of ``a`` on ``b`` (both components pooled, means removed)."""
    sel = where & np.all(np.isfinite(a), -1) & np.all(np.isfinite(b), -1)
    x = b[sel] - b[sel].mean(axis=0)
    y = a[sel] - a[sel].mean(axis=0)
    return float((x * y).sum() / (x * x).sum())


def matched(u: np.ndarray, res) -> np.ndarray:
    """A peer's field ``u`` (px) through the transfer of glassdist's displacement output, per carrier.

    The whole documented transfer (:meth:`glassdist.analyzer.transfer.InstrumentTransfer.response`,
    docs/explanation/transfer-function.md): Block F's Gaussian ``G_i``, or after F5's ``n`` demodulations
    (``res.demodulations``) ``(1 - (1 - G_i B)^n) / B`` (with its photo passes, ``res.photo_passes``,
    from the low-pass of ``res.restart_sigma_px``, as there), times the block means of the analysis grid
    and the cubic B-spline from it to every pixel, applied in the spectrum of the whole field
    (periodic FFT on the field extended by odd reflection).
    """
    import scipy.fft as sfft

    from glassdist.analyzer import deform as D
    from glassdist.analyzer.demodulate import covariances as _covariances
    from glassdist.analyzer.demodulate import demodulation_blur_px2 as _demodulation_blur_px2
    from glassdist.analyzer.transfer import InstrumentTransfer

    ks = res.carriers
    blur = _demodulation_blur_px2(ks, _covariances(ks, res.params), res.params)
    # the step (B) of the demodulation grid the analysis measured on (F5 may refine the one pass's), the
    # analysis grid's block means of it and the interpolation from the analysis grid to the pixels
    fine, coarse = res.demodulation_step_px, res.sampling_step_px
    block = int(round(coarse[0] / fine[0]))
    tr = InstrumentTransfer(blur, fine_step_px=fine, block=block, interp_step_px=None if coarse == (1.0, 1.0) else coarse,
                            passes=res.demodulations - res.photo_passes, photo_passes=res.photo_passes,
                            restart_sigma_px=res.restart_sigma_px)
    ph = D.displacement_to_phase(u, ks)
    h, w = u.shape[:2]
    pad = 64
    out = []
    for i in range(2):
        ext = np.pad(ph[..., i], pad, mode="reflect", reflect_type="odd")
        fy = sfft.fftfreq(ext.shape[0])[:, None]
        fx = sfft.rfftfreq(ext.shape[1])[None, :]
        g = tr.response(i, fy, fx)
        out.append(sfft.irfft2(sfft.rfft2(ext) * g, s=ext.shape)[pad : pad + h, pad : pad + w])
    return D.phase_to_displacement_px(np.stack(out, axis=-1), ks)


def analyze_waves(ref: np.ndarray, img: np.ndarray, params: dict | None = None):
    """glassdist's Comparative analysis of the photo (the settings of the README's Quick start)."""
    from glassdist import analyze

    return analyze(img, reference=ref, pattern="checkerboard", pitch_mm=5.0, distance_m=DISTANCE_M, detrend_degree=3,
                   params=params or None)


def field_px(res) -> np.ndarray:
    """glassdist's displacement as ``u`` (px, ``img(r) = ref(r - u(r))``), NaN outside its valid region."""
    u = -res.displacement_mm / res.mm_per_px
    u[~res.valid] = np.nan
    return u


SCALES = np.round(np.arange(0.90, 1.2001, 0.02), 2)


def best_scale(ref: np.ndarray, img: np.ndarray, u: np.ndarray, where: np.ndarray) -> float:
    """The photo's own verdict on a field's amplitude: the factor ``s`` on its deviations from their mean.

    ``u_s = mean + s (u - mean)`` over ``where``; the ``s`` of :data:`SCALES` whose warped
    reference correlates best with the photo, refined by a parabola through its neighbours.
    No transfer model and no peer enter it; a field attenuated by a factor ``a`` reads about ``1 / a``.
    """
    mean = np.nanmean(np.where(where[..., None], u, np.nan), axis=(0, 1))
    c = np.array([correlation(warp_reference(ref, mean + s * (u - mean)), img, where) for s in SCALES])
    i = int(np.argmax(c))
    if 0 < i < len(c) - 1:
        den = c[i - 1] - 2 * c[i] + c[i + 1]
        step = SCALES[1] - SCALES[0]
        return float(SCALES[i] + (0.5 * step * (c[i - 1] - c[i + 1]) / den if den < 0 else 0.0))
    return float(SCALES[i])


BANDS_PX = ((0, 3), (3, 6), (6, 10), (10, 20), (20, None))


def border_bands(res, warped: dict, img: np.ndarray) -> list[dict]:
    """Each score by distance from the border of glassdist's region and by what lies beyond that border.

    Per band of distance (px, ``BANDS_PX``) from the nearest pixel outside ``res.valid``, and within
    it per quality label of that nearest pixel (image edge, beyond measurable distortion, ...): its
    share of the region and the correlation of each warped reference with the photo there.
    """
    from scipy import ndimage

    from glassdist.analyzer.region import LABELS

    valid = res.valid
    dist, idx = ndimage.distance_transform_edt(valid, return_indices=True)
    beyond = np.asarray(res.quality)[idx[0], idx[1]]
    out = []
    for lo, hi in BANDS_PX:
        band = valid & (dist > lo) & (dist <= (np.inf if hi is None else hi))
        for label in [None, *np.unique(beyond[band]).tolist()]:
            m = band if label is None else band & (beyond == label)
            if m.sum() < 200:  # too few pixels for a correlation worth reading
                continue
            out.append({"band_px": [lo, hi], "beyond": "all" if label is None else LABELS[int(label)],
                        "share": float(m.sum() / valid.sum()),
                        "correlation": {k: correlation(w, img, m) for k, w in warped.items()}})
    return out


def agree(a: np.ndarray, b: np.ndarray, period: float) -> np.ndarray:
    """Pixels where two fields (px) agree within ``TOL_PERIODS`` carrier period on both components."""
    with np.errstate(invalid="ignore"):
        return np.max(np.abs(a - b), axis=-1) < TOL_PERIODS * period


def run(image: Path, reference: Path, params: dict) -> dict:
    from glassdist.io import read_image

    ref = read_image(reference)
    img = read_image(image)
    t0 = time.perf_counter()
    res = analyze_waves(ref, img, params)
    valid = res.valid
    t_gd = time.perf_counter() - t0
    period = max(res.carriers.k1.period_px, res.carriers.k2.period_px)
    fields = {"glassdist": field_px(res), "FCD": fcd_displacement(ref, img),
              "Farneback": farneback_displacement(ref, img, **FARNEBACK)}

    both = agree(fields["FCD"], fields["Farneback"], period)
    for k in ("FCD", "Farneback"):
        fields[f"{k} matched"] = matched(fields[k], res)
    # Smoothed over the same support (glassdist's region) for every method: a peer's values where
    # glassdist has none (the excluded rings) would otherwise leak into the comparison near its border.
    from scipy import ndimage

    inner = ndimage.distance_transform_edt(valid) > period
    sm = {k: smooth_nan(np.where(valid[..., None], v, np.nan), period) for k, v in fields.items()}
    rows, warped_by = {}, {}
    for k, u in fields.items():
        warped = warp_reference(ref, u)
        if k in ("glassdist", "Farneback"):
            warped_by[k] = warped
        rows[k] = {
            "correlation": correlation(warped, img, valid),
            "correlation_inner": correlation(warped, img, inner),
            "amplitude_vs_fcd": slope(sm[k], sm["FCD matched"], valid),
        }
        if not k.endswith("matched"):
            rows[k]["best_scale"] = best_scale(ref, img, u, valid)
    cov = float((valid & both).sum() / max(both.sum(), 1))
    inside = float((valid & both).sum() / max(valid.sum(), 1))
    acc = float((valid & agree(fields["glassdist"], fields["FCD"], period)).sum() / max(valid.sum(), 1))
    from glassdist.analyzer.region import LABELS

    _, n_parts = ndimage.label(valid)
    dropped = both & ~valid
    q = np.asarray(res.quality)[dropped]
    dropped_by = {LABELS[int(k)]: float(c / max(dropped.sum(), 1)) for k, c in zip(*np.unique(q, return_counts=True))}
    return {"period_px": period, "analysed": float(valid.mean()), "inner_share": float(inner.sum() / max(valid.sum(), 1)),
            "farneback": FARNEBACK, "agree_area": float(both.mean()), "coverage": cov,
            "inside": inside, "accuracy": acc, "parts": int(n_parts), "dropped_by_label": dropped_by, "glassdist_s": t_gd,
            "methods": rows,
            "warnings": list(res.warnings), "quality_counts": res.quality_counts(),
            "border_bands": border_bands(res, warped_by, img)}


# Replicas of the photo with a known displacement: each peer's field of the photo, smoothed by these
# carrier periods (finer: the rings' steeper flanks kept), scaled by the factor the photo prefers for it.
REPLICA_SMOOTHING_PERIODS = (0.25, 0.5, 1.0)
REPLICA_SEED = 25
# The amplitude is also scored this many carrier periods inside glassdist's region, away from its border.
REPLICA_INNER_PERIODS = 3.0


def noise_std(a: np.ndarray) -> float:
    """White-noise standard deviation of an image, Immerkaer (1996): mean |Laplacian difference| x sqrt(pi/2)/6."""
    from scipy import ndimage

    m = np.array([[1.0, -2.0, 1.0], [-2.0, 4.0, -2.0], [1.0, -2.0, 1.0]])
    c = ndimage.convolve(np.asarray(a, float), m)[1:-1, 1:-1]
    return float(np.sqrt(np.pi / 2) * np.abs(c).mean() / 6)


def replica_truth(field: np.ndarray, smoothing_px: float, scale: float) -> np.ndarray:
    """A replica's displacement (px): ``field`` Gaussian-smoothed by ``smoothing_px``, scaled by ``scale`` about its mean."""
    from scipy import ndimage

    base = np.stack([ndimage.gaussian_filter(field[..., c], smoothing_px) for c in range(2)], -1)
    mean = base.mean(axis=(0, 1))
    return mean + scale * (base - mean)


def replica(ref: np.ndarray, u: np.ndarray, sigma: float, seed: int) -> np.ndarray:
    """``ref(r - u(r))`` (cubic spline, mirrored at the edges) plus independent white noise of ``sigma``."""
    from scipy import ndimage

    h, w = ref.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    out = ndimage.map_coordinates(np.asarray(ref, float), [yy - u[..., 1], xx - u[..., 0]], order=3, mode="mirror")
    return out + np.random.default_rng(seed).normal(0.0, sigma, out.shape)


def replicas(image: Path, reference: Path, params: dict) -> dict:
    """Every method on replicas of the photo whose displacement is known.

    The truth of a replica is a peer's field of the photo (FCD's or Farneback's, never glassdist's),
    Gaussian-smoothed by :data:`REPLICA_SMOOTHING_PERIODS` carrier periods and scaled about its mean
    by the factor the photo prefers for that field (``best_scale``): rings as strong as the photo's,
    as steep as the smoothing leaves them. The replica is the reference warped by it (``replica``),
    plus independent noise at the reference's level (``noise_std``), so its noise is the reference's
    (resampled) and as much again. Scores, over glassdist's region of the replica, all fields
    smoothed by one carrier period over it as in ``run``:

    * **amplitude against the truth**: ``slope`` of the field on the truth, over the whole region,
      without the 1 % of its pixels where the field is furthest from the truth, and more than
      :data:`REPLICA_INNER_PERIODS` carrier periods from the region's border;
    * **against FCD**: the photo's bound, glassdist's slope on FCD's field through glassdist's transfer;
    * **off**: the share of the region where the field (unsmoothed) is more than a quarter carrier
      period from the truth: whole-period slips of the unwrapping show here;
    * **phi_eff**: each field's phi_eff by the plain evaluation
      (:func:`glassdist.experiments.transfer.independent_phi_eff`: glassdist's detrend region, degree 3
      and sigma, the scale ``mm_per_px`` without perspective) against the truth's, and glassdist's own
      phi_eff map against the truth's, more than 3 sigma inside glassdist's trusted pixels;
    * the correlation with the replica and the scale the replica prefers, as on the photo.
    """
    from scipy import ndimage

    from glassdist.experiments.transfer import _interior, independent_phi_eff
    from glassdist.io import read_image

    ref, img = read_image(reference), read_image(image)
    res = analyze_waves(ref, img, params)
    period = max(res.carriers.k1.period_px, res.carriers.k2.period_px)
    sigma = noise_std(ref)
    peers = {"FCD": fcd_displacement(ref, img), "Farneback": farneback_displacement(ref, img, **FARNEBACK)}
    rows = []
    for i, (src, field) in enumerate(peers.items()):
        scale = best_scale(ref, img, field, res.valid)
        for j, periods in enumerate(REPLICA_SMOOTHING_PERIODS):
            truth = replica_truth(field, periods * period, scale)
            rep = replica(ref, truth, sigma, REPLICA_SEED + 10 * i + j)
            t0 = time.perf_counter()
            r = analyze_waves(ref, rep, params)
            t = time.perf_counter() - t0
            valid = r.valid
            f = {"glassdist": field_px(r), "FCD": fcd_displacement(ref, rep),
                 "Farneback": farneback_displacement(ref, rep, **FARNEBACK)}
            sm = {k: smooth_nan(np.where(valid[..., None], v, np.nan), period) for k, v in f.items()}
            sm_truth = smooth_nan(np.where(valid[..., None], truth, np.nan), period)
            fcd_matched = smooth_nan(np.where(valid[..., None], matched(f["FCD"], r), np.nan), period)
            grad = [np.hypot(*np.gradient(truth[..., c])) for c in range(2)]  # |grad u_x|, |grad u_y|
            deep = ndimage.distance_transform_edt(valid) > REPLICA_INNER_PERIODS * period
            # phi_eff of each field by the plain evaluation (glassdist's settings: its detrend region, degree 3,
            # its sigma; the scale mm_per_px, no perspective), against the truth's, 3 sigma inside the trusted pixels
            s_px = r.sigma_mm / r.mm_per_px

            def plain_phi(u):
                return independent_phi_eff(-np.nan_to_num(u) * r.mm_per_px, r.detrend_region, jacobian=np.eye(2) * r.mm_per_px,
                                           sigma_px=s_px, degree=3, distance_m=DISTANCE_M)

            phi_truth = plain_phi(truth)
            inner_phi = _interior(r.trusted, s_px) & np.isfinite(phi_truth) & np.isfinite(r.phi_eff_mD)
            methods = {}
            for k, u in f.items():
                err = np.max(np.abs(sm[k] - sm_truth), axis=-1)
                worst = err > np.nanpercentile(err[valid], 99)
                methods[k] = {"amplitude_vs_truth": slope(sm[k], sm_truth, valid),
                              "amplitude_vs_truth_99": slope(sm[k], sm_truth, valid & ~worst),
                              "amplitude_vs_truth_inner": slope(sm[k], sm_truth, deep),
                              "off_quarter_period": float(np.mean(np.max(np.abs(u - truth), axis=-1)[valid] > 0.25 * period)),
                              "phi_eff_plain_vs_truth": slope(plain_phi(u)[..., None], phi_truth[..., None], inner_phi),
                              "correlation": correlation(warp_reference(ref, u), rep, valid),
                              "best_scale": best_scale(ref, rep, u, valid)}
            rows.append({"truth_from": src, "smoothing_periods": periods, "scale": scale,
                         "gradient_p99": float(np.percentile(np.maximum(*grad)[valid], 99)),
                         "analysed": float(valid.mean()), "inner_share": float(deep.sum() / valid.sum()),
                         "glassdist_s": t, "demodulations": int(r.demodulations),
                         "glassdist_vs_fcd": slope(sm["glassdist"], fcd_matched, valid),
                         "phi_eff_stack_vs_truth": slope(r.phi_eff_mD[..., None], phi_truth[..., None], inner_phi),
                         "phi_interior": float(inner_phi.sum() / valid.sum()), "methods": methods})
    return {"period_px": period, "noise_std_added": sigma, "seed": REPLICA_SEED, "rows": rows}


def replica_table(rec: dict) -> str:
    lines = [f"Replicas of the waves photo with a known displacement (carrier period {rec['period_px']:.2f} px; "
             f"independent noise of {rec['noise_std_added']:.4f} added, the reference's level; seed {rec['seed']} and "
             "up). Per replica: the peer whose field of the photo is the truth, its smoothing (carrier periods), the "
             "scale the photo prefers for that field, the truth's displacement gradient (p99 over glassdist's region) "
             "and glassdist's region. Per method: its amplitude against the truth (one period of smoothing over "
             "glassdist's region) over the whole region, without its 1 % furthest from the truth, and more than "
             f"{REPLICA_INNER_PERIODS:g} periods inside; the share of the region where it is more than a quarter "
             "period off the truth (unsmoothed); its phi_eff by the plain evaluation against the truth's (more than "
             "3 sigma inside glassdist's trusted pixels; on glassdist's row also its own phi_eff map's, after the "
             "slash); the correlation of the reference warped by it with the "
             "replica; the scale the replica prefers. On glassdist's row: its amplitude on FCD's field through "
             "its transfer, the waves photo's bound.", "",
             "| truth | gradient p99 | analysed | method | amplitude / truth | without the worst 1 % | "
             f"> {REPLICA_INNER_PERIODS:g} periods inside | off by > 1/4 period | phi_eff / truth | correlation | "
             "preferred scale | amplitude / FCD matched |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rec["rows"]:
        head = (f"{r['truth_from']}, {r['smoothing_periods']:g}, x {r['scale']:.3f} | {r['gradient_p99']:.2f} | "
                f"{100 * r['analysed']:.1f} % ({100 * r['inner_share']:.0f} % inside)")
        for k in ("glassdist", "FCD", "Farneback"):
            m = r["methods"][k]
            vs = f"{r['glassdist_vs_fcd']:.3f}" if k == "glassdist" else ""
            phi = f"{m['phi_eff_plain_vs_truth']:.4f}" + (f" / {r['phi_eff_stack_vs_truth']:.4f}" if k == "glassdist" else "")
            lines.append(f"| {head} | {k} | {m['amplitude_vs_truth']:.3f} | {m['amplitude_vs_truth_99']:.3f} | "
                         f"{m['amplitude_vs_truth_inner']:.3f} | {100 * m['off_quarter_period']:.2f} % | {phi} | "
                         f"{m['correlation']:.4f} | {m['best_scale']:.3f} | {vs} |")
            head = " | | "
    return "\n".join(lines)

def farneback_sweep(image: Path, reference: Path) -> dict:
    """The Farneback peer over a grid of its settings: the peers' agreement area and glassdist's share in it."""
    import itertools

    from glassdist.io import read_image

    ref, img = read_image(reference), read_image(image)
    res = analyze_waves(ref, img)
    valid = res.valid
    period = max(res.carriers.k1.period_px, res.carriers.k2.period_px)
    fcd = fcd_displacement(ref, img)
    rows = []
    for win, it, (pn, ps) in itertools.product((11, 15, 21, 31), (10, 30), ((5, 1.1), (7, 1.5))):
        u = farneback_displacement(ref, img, win, it, pn, ps)
        both = agree(fcd, u, period)
        rows.append({"winsize": win, "iterations": it, "poly_n": pn, "poly_sigma": ps, "agree_area": float(both.mean()),
                     "coverage": float((valid & both).sum() / max(both.sum(), 1)),
                     "inside": float((valid & both).sum() / max(valid.sum(), 1)),
                     "correlation": correlation(warp_reference(ref, u), img, valid)})
    glassdist_corr = correlation(warp_reference(ref, field_px(res)), img, valid)
    return {"period_px": period, "analysed": float(valid.mean()), "setting": FARNEBACK, "glassdist_correlation": glassdist_corr,
            "rows": rows}


def sweep_table(rec: dict) -> str:
    best = max(rec["rows"], key=lambda r: r["agree_area"])
    st = rec["setting"]
    lines = [f"glassdist analyses {100 * rec['analysed']:.1f} % of the photo (carrier period {rec['period_px']:.2f} px); "
             f"its field's correlation with the photo (reference warped by it) is {rec['glassdist_correlation']:.4f} over "
             f"that region. The benchmark's setting: window {st['winsize']}, {st['iterations']} iterations, polynomial "
             f"{st['poly_n']} / {st['poly_sigma']}.", "",
             "| window px | iterations | polynomial n / sigma | peers agree (share of the photo) | coverage of it | "
             "glassdist valid inside it | Farneback's correlation with the photo |", "|---|---|---|---|---|---|---|"]
    for r in rec["rows"]:
        mark = " **(largest)**" if r is best else ""
        lines.append(f"| {r['winsize']} | {r['iterations']} | {r['poly_n']} / {r['poly_sigma']} | "
                     f"{100 * r['agree_area']:.1f} %{mark} | {100 * r['coverage']:.1f} % | {100 * r['inside']:.1f} % | "
                     f"{r['correlation']:.4f} |")
    top = max(rec["rows"], key=lambda r: r["correlation"])
    lines += ["", f"Largest agreement area of the peers: {100 * best['agree_area']:.1f} % of the photo (coverage "
              f"{100 * best['coverage']:.1f} %, glassdist's region inside it {100 * best['inside']:.1f} %). Highest "
              f"correlation of a Farneback field with the photo: {top['correlation']:.4f} (window {top['winsize']}, "
              f"{top['iterations']} iterations, polynomial {top['poly_n']} / {top['poly_sigma']}), against "
              f"glassdist's {rec['glassdist_correlation']:.4f}."]
    return "\n".join(lines)


def table(rec: dict) -> str:
    lines = ["| method | correlation with the photo (ref warped by the field) | the same, more than 1 period inside "
             f"({100 * rec['inner_share']:.0f} % of the region) | amplitude / FCD matched (+1 period smoothing) | "
             "scale of the field the photo prefers |",
             "|---|---|---|---|---|"]
    for k, r in rec["methods"].items():
        best = f"{r['best_scale']:.3f}" if "best_scale" in r else "—"
        lines.append(f"| {k} | {r['correlation']:.4f} | {r['correlation_inner']:.4f} | {r['amplitude_vs_fcd']:.3f} | {best} |")
    lines += ["", "By distance from the border of glassdist's region and by what lies beyond it (the nearest pixel "
              "outside the region): share of the region, correlation with the photo glassdist / Farneback.", "",
              "| distance from the border | beyond it | share of the region | glassdist | Farneback |", "|---|---|---|---|---|"]
    for b in rec["border_bands"]:
        lo, hi = b["band_px"]
        where = f"{lo}–{hi} px" if hi is not None else f"> {lo} px"
        c = b["correlation"]
        lines.append(f"| {where} | {b['beyond']} | {100 * b['share']:.1f} % | {c['glassdist']:.4f} | {c['Farneback']:.4f} |")
    drop = ", ".join(f"{k} {100 * v:.0f} %" for k, v in sorted(rec["dropped_by_label"].items(), key=lambda kv: -kv[1]))
    lines += ["", f"Labels of the agreement area glassdist leaves out: {drop}."]
    lines += ["", "| carrier period | analysed | peers agree (0.1 period) | coverage of it | valid inside it | "
              "valid agreeing with FCD | connected parts |", "|---|---|---|---|---|---|---|",
              f"| {rec['period_px']:.2f} px | {100 * rec['analysed']:.1f} % | {100 * rec['agree_area']:.1f} % | "
              f"{100 * rec['coverage']:.1f} % | {100 * rec['inside']:.1f} % | {100 * rec['accuracy']:.1f} % | "
              f"{rec['parts']} |"]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    from _data import REAL_PHOTOS, real_photos

    ap.add_argument("--image", type=Path, default=REAL_PHOTOS / "distorted_waves.bmp")
    ap.add_argument("--reference", type=Path, default=REAL_PHOTOS / "reference.png")
    ap.add_argument("--params", default="{}", help="analyzer parameter overrides, JSON")
    ap.add_argument("--out", type=Path, help="write the table (markdown) and the record (FILE.json beside it)")
    ap.add_argument("--farneback-sweep", action="store_true", help="the Farneback peer over a grid of its settings")
    ap.add_argument("--replica", action="store_true", help="every method on replicas of the photo with a known displacement")
    a = ap.parse_args(argv)
    if REAL_PHOTOS in (a.image.parent, a.reference.parent):
        real_photos()
    if a.replica:
        rec = replicas(a.image, a.reference, json.loads(a.params))
        text = replica_table(rec)
        print(text)
        if a.out:
            write_record(a.out, "bench_waves_peers.py", argv, text, rec)
        return 0
    if a.farneback_sweep:
        rec = farneback_sweep(a.image, a.reference)
        text = sweep_table(rec)
        print(text)
        if a.out:
            write_record(a.out, "bench_waves_peers.py", argv, text, rec)
        return 0
    rec = run(a.image, a.reference, json.loads(a.params))
    text = table(rec)
    print(text)
    print("warnings:", *rec["warnings"], sep="\n  ")
    if a.out:
        write_record(a.out, "bench_waves_peers.py", argv, text, rec)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
