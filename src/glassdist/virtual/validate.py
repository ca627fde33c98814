"""Validation within the Virtual Pipeline: Analyzer vs Optical Theoretical Model (paper §3.1, Table 2).

Both branches start from the same scene. Branch 1 renders the distorted (and
glass-less) image and runs the Distortion Analyzer; branch 2 evaluates the
analytical model on the camera pixel grid. The analytical displacement then
goes through the *same* evaluation stack (A2 detrend, metric-anchored smoothing,
A3) with the analyzer's ``mm_per_px``, ``sigma_mm`` and ``detrend_degree``, and
the two are compared on their common valid region.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .._version import __version__
from ..errors import InputError
from ..render import get_renderer, landing_points, render_scene
from ..scene import Scene
from ..theory import Prediction, analysis_params, predict_channels, predict_displacement, reflection_geometry

__all__ = ["Validation", "procrustes", "compare", "compare_with_scene", "exact_truth", "validate_scene", "CHANNELS"]

CHANNELS = ("phi_eff_mD", "phi_shear_mD", "phi_total_mD")
_SHORT = {"phi_eff_mD": "phi_eff", "phi_shear_mD": "phi_shear", "phi_total_mD": "phi_total"}


def procrustes(source: np.ndarray, target: np.ndarray) -> tuple[float, float]:
    """Rotation and isotropic scale best aligning 2-D vectors ``source`` to ``target``.

    Parameters
    ----------
    source, target : ndarray (N, 2)
        Paired vectors (x, y); both are centred first.

    Returns
    -------
    rotation_deg : float
        Angle of the rotation applied to ``source``, degrees from +x towards +y.
    scale : float
        Isotropic scale ``s``.

    Notes
    -----
    Orthogonal Procrustes with scaling: minimise
    :math:`\\lVert s\\,X R - Y\\rVert_F` over rotations ``R`` (det +1); with
    :math:`X^T Y = U \\Sigma V^T`, :math:`R = U\\,\\mathrm{diag}(1, \\det UV^T)\\,V^T`
    and :math:`s = \\mathrm{tr}(\\Sigma D) / \\lVert X\\rVert_F^2` (Schonemann 1966).
    """
    X = np.asarray(source, float) - np.mean(source, axis=0)
    Y = np.asarray(target, float) - np.mean(target, axis=0)
    U, S, Vt = np.linalg.svd(X.T @ Y)
    D = np.diag([1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    scale = float(np.trace(np.diag(S) @ D) / np.sum(X * X))
    return float(np.degrees(np.arctan2(R[0, 1], R[0, 0]))), scale


def _mean_abs(a: np.ndarray, sel: np.ndarray) -> float:
    return float(np.mean(np.abs(a[sel])))


def _corr(a: np.ndarray, b: np.ndarray, sel: np.ndarray) -> float:
    x, y = a[sel] - a[sel].mean(), b[sel] - b[sel].mean()
    den = np.sqrt(np.sum(x * x) * np.sum(y * y))
    return float(np.sum(x * y) / den) if den > 0 else float("nan")


@dataclass(frozen=True)
class Validation:
    """Analyzer vs analytical model on their common valid region.

    Attributes
    ----------
    analysis : glassdist.analyzer.AnalysisResult
    analytical : glassdist.analyzer.Channels
        The model through the shared evaluation stack.
    exact : glassdist.analyzer.Channels or None
        The tracer's exact landing displacement through the same stack (ground truth).
    valid : ndarray of bool (H, W)
        Common valid region of the comparison.
    metrics : dict
        ``ratios`` (mean |phi| analyzer / analytical), ``correlations`` (Pearson,
        maps), ``procrustes`` (rotation_deg, scale), ``model_vs_exact`` ratios,
        per-branch ``statistics``.
    """

    analysis: object
    analytical: object
    exact: object
    valid: np.ndarray
    metrics: dict = field(default_factory=dict)


def compare(analysis, analytical, valid: np.ndarray, exact=None) -> Validation:
    """Compare an :class:`AnalysisResult` with the analytical channels (Table 2 of the paper)."""
    sel = np.asarray(valid, bool).copy()
    for ch in (analysis, analytical) + (() if exact is None else (exact,)):
        for name in CHANNELS:
            sel &= np.isfinite(getattr(ch, name))
        sel &= np.all(np.isfinite(ch.displacement_detrended_mm), axis=-1)
    if sel.sum() < 16:
        raise InputError("the analyzer and the analytical model share fewer than 16 valid pixels; check the scene framing")
    for name in CHANNELS:  # every ratio below divides by the model's (or the truth's) mean |phi|
        for what, ch in (("analytical model", analytical), ("exact truth", exact)):
            if ch is not None and not _mean_abs(getattr(ch, name), sel) > 0:
                raise InputError(
                    f"the {what} predicts no {name} at all on the {int(sel.sum())} compared pixels, so there is no "
                    "ratio to validate; check the scene (e.g. a pane thickness or distance so large that the "
                    "deformation no longer shows)")
    m: dict = {"ratios": {}, "correlations": {}, "statistics": {"analyzer": {}, "analytical": {}}}
    for name in CHANNELS:
        a, b = getattr(analysis, name), getattr(analytical, name)
        m["ratios"][_SHORT[name]] = _mean_abs(a, sel) / _mean_abs(b, sel)
        m["correlations"][_SHORT[name]] = _corr(a, b, sel)
        m["statistics"]["analyzer"][_SHORT[name]] = {"mean_abs": _mean_abs(a, sel), "std": float(np.std(a[sel]))}
        m["statistics"]["analytical"][_SHORT[name]] = {"mean_abs": _mean_abs(b, sel), "std": float(np.std(b[sel]))}
    rot, scale = procrustes(analysis.displacement_detrended_mm[sel], analytical.displacement_detrended_mm[sel])
    m["procrustes"] = {"rotation_deg": rot, "scale": scale}
    if exact is not None:
        m["model_vs_exact"] = {
            _SHORT[n]: _mean_abs(getattr(analytical, n), sel) / _mean_abs(getattr(exact, n), sel) for n in CHANNELS
        }
        m["analyzer_vs_exact"] = {
            _SHORT[n]: _mean_abs(getattr(analysis, n), sel) / _mean_abs(getattr(exact, n), sel) for n in CHANNELS
        }
    m["valid_fraction"] = float(sel.mean())
    return Validation(analysis, analytical, exact, sel, m)


def exact_truth(scene: Scene, model: Prediction) -> Prediction:
    """The exact tracer's landing displacement on the camera pixel grid (the ground truth).

    Parameters
    ----------
    scene : Scene
    model : Prediction
        The scene's :func:`glassdist.theory.predict_displacement` (lends its incidence angles).

    Returns
    -------
    Prediction
        ``displacement_mm`` and ``status`` of :func:`glassdist.render.landing_points`.
    """
    lp = landing_points(scene)
    return Prediction(lp.displacement_mm, lp.status, model.incidence_deg, {})


def compare_with_scene(result, scene: Scene, *, model: Prediction, truth: Prediction | None = None,
                       truth_region: np.ndarray | None = None) -> Validation:
    """Pass the model (and the truth) through the evaluation stack with the analyzer's settings and compare.

    Parameters
    ----------
    result : AnalysisResult
        The analyzer's run on an image of ``scene``.
    scene : Scene
    model : Prediction
        The Optical Theoretical Model on the camera pixel grid.
    truth : Prediction, optional
        The exact landing displacement (:func:`exact_truth`).
    truth_region : ndarray of bool, optional
        The pixels the model and the truth are detrended on; default ``result.detrend_region``,
        the documented one. ``result.valid`` reproduces records made before the detrend region
        was stated, whose truth also saw the ring of partial blocks the A2 fit never sees
        (``benchmarks/bench_yardstick.py``).

    Returns
    -------
    Validation
        :func:`compare` on the model's region within the analyzer's trusted pixels; the
        stack runs with the analyzer's ``sigma_mm``, ``detrend_degree``, ``mm_per_px``,
        A1 mode and region: the truth is detrended on the analyzer's detrend region
        (``result.detrend_region``, the whole blocks its A2 fit sees; ``valid`` adds a ring
        of partial blocks the fit never saw).
    """
    board = 1.0 if result.optics is None else result.optics.magnification  # reflection: the board's mm per px
    settings = dict(
        sigma_mm=result.sigma_mm, detrend_degree=result.detrend_degree, mm_per_px=result.mm_per_px * board,
        valid=result.detrend_region if truth_region is None else truth_region,
        projective=result.params.a1_mode == "projective",
    )
    _, analytical, region = predict_channels(scene, prediction=model, **settings)
    exact = None if truth is None else predict_channels(scene, prediction=truth, **settings)[1]
    # compared where the analyzer's statistics are taken (trusted: outside the guard band)
    return compare(result, analytical, region & result.trusted, exact=exact)


def validate_scene(
    scene: Scene,
    *,
    method: str = "direct",
    engine: str = "exact",
    params=None,
    progress: Callable[[str, int, int], None] | None = None,
    renders: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[Validation, dict]:
    """Run both branches of the Virtual Pipeline on a scene and compare them.

    Parameters
    ----------
    scene : Scene
    method : {'direct', 'comparative'}
        Analyzer method (the glass-less reference is rendered in both cases; it
        is given to the analyzer only for 'comparative').
    engine : str
        Render engine (:func:`glassdist.render.get_renderer`).
    params : AnalyzerParams, optional
        Default :func:`glassdist.theory.analysis_params` of the scene.
    progress : callable(stage, done, total), optional
    renders : (ndarray, ndarray), optional
        ``(distorted, reference)`` images of this scene already rendered by ``engine``
        (:func:`glassdist.render.render_scene`, without and with ``reference=True``), so that
        both methods are judged on one render pair, as in the paper's Table 2; rendered here
        when omitted. Their shape must be the scene camera's ``(rows, columns)``.

    Returns
    -------
    validation : Validation
    record : dict
        JSON-serialisable record (``validation.json``) including the images under
        the keys ``"_distorted"`` / ``"_reference"`` (arrays; not serialised).
    """
    from ..analyzer import analyze, analyze_reflection

    if method not in ("direct", "comparative"):
        raise InputError(f"unknown method '{method}'; use 'direct' or 'comparative'")
    p = analysis_params(scene) if params is None else params
    eng = get_renderer(engine)
    timings = {}
    t0 = time.perf_counter()
    if renders is None:
        distorted, reference = _render_pair(scene, eng, progress)
        timings["render_s"] = time.perf_counter() - t0
    else:
        distorted, reference = (np.asarray(a) for a in renders)
        want = tuple(scene.camera.pixels[::-1])
        if distorted.shape != want or reference.shape != want:
            raise InputError(f"the renders given are {distorted.shape} and {reference.shape} px, the scene's camera "
                             f"{want}; render this scene (glassdist.render.render_scene) or leave renders out")
    t0 = time.perf_counter()
    ref = reference if method == "comparative" else None
    if scene.reflection:  # phi in reflective power on the pane (glassdist.analyzer.reflection)
        result = analyze_reflection(distorted, pitch_mm=scene.backdrop.pitch_mm, geometry=reflection_geometry(scene),
                                    reference=ref, params=p)
    else:
        result = analyze(distorted, pitch_mm=scene.backdrop.pitch_mm, distance_m=scene.backdrop.distance_m,
                         reference=ref, params=p)
    timings["analyze_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    model = predict_displacement(scene)
    timings["model_s"] = time.perf_counter() - t0
    val = compare_with_scene(result, scene, model=model, truth=exact_truth(scene, model))
    record = {
        **_validation_record(scene, result, getattr(eng, "name", engine)),
        **val.metrics,
        "timings": timings,
        "_distorted": distorted,
        "_reference": reference,
    }
    return val, record


def _render_pair(scene: Scene, engine, progress) -> tuple[np.ndarray, np.ndarray]:
    """The distorted and the glass-less image of a scene, progress reported per image."""

    def stage(name):
        return None if progress is None else (lambda done, total: progress(name, done, total))

    distorted = render_scene(scene, engine=engine, progress=stage("render distorted"))
    reference = render_scene(scene, engine=engine, reference=True, progress=stage("render reference"))
    return distorted, reference


def _validation_record(scene: Scene, result, engine: str) -> dict:
    """The settings part of ``validation.json``: scene, method, engine, image size and the analyzer's run."""
    return {
        "glassdist_version": __version__,
        "scene": scene.name,
        "method": result.method,
        "engine": engine,
        "samples_per_pixel": scene.render.samples_per_pixel,
        "seed": scene.render.seed,
        "image_size": list(scene.camera.pixels),
        "analyzer": {
            "mm_per_px": result.mm_per_px,
            "sigma_mm": result.sigma_mm,
            "detrend_degree": result.detrend_degree,
            "a1_mode": result.params.a1_mode,
            "valid_fraction": float(result.valid.mean()),
            "warnings": list(result.warnings),
            "params": result.params.resolved(),
        },
    }
