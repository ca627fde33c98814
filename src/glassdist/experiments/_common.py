"""Shared machinery of the paper's virtual experiments (§3): render once, evaluate many times.

Every experiment follows the Virtual Pipeline of :mod:`glassdist.virtual`: a scene
is rendered (distorted and, when needed, glass-less), the Distortion Analyzer is run
on the image, and the Optical Theoretical Model *and* the exact landing-point truth
of the tracer are passed through the same evaluation stack (A2 detrend,
metric-anchored smoothing, A3) with the analyzer's ``mm_per_px``, ``sigma_mm``,
``detrend_degree`` and valid region, then compared by
:func:`glassdist.virtual.compare`. The rendering and the two scene-only
predictions are computed once per scene (:func:`render_inputs`) and reused for
every method and parameter set (:func:`evaluate`).

Lengths in mm, L in m, optical power in mD.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from .._version import __version__
from ..errors import InputError
from ..render import get_renderer, render_scene
from ..scene import Scene, load_scene
from ..theory import Prediction, analysis_params, predict_displacement, read_params_file
from ..virtual import Validation, compare_with_scene, exact_truth

__all__ = [
    "Inputs",
    "RunOptions",
    "SceneRun",
    "scaled_scene",
    "render_inputs",
    "evaluate",
    "run_scenes",
    "common_region",
    "settings_record",
    "region_stats",
    "relative_difference",
    "validation_record",
    "write_json",
    "share_fig_ax",
    "save_figure",
    "map_panel",
    "shared_limit",
    "ExperimentResult",
    "bound",
    "bounds_table",
    "write_experiment",
]

log = logging.getLogger(__name__)

SHORT = {"phi_eff_mD": "phi_eff", "phi_shear_mD": "phi_shear", "phi_total_mD": "phi_total"}


@dataclass(frozen=True)
class Inputs:
    """A rendered scene and its two scene-only predictions (computed once).

    Attributes
    ----------
    scene : Scene
    engine : str
        Name of the render engine.
    distorted : ndarray (H, W)
        Image through the glass, grey in [0, 1].
    reference : ndarray (H, W) or None
        Glass-less image (None when not rendered).
    model : Prediction
        Optical Theoretical Model on the camera pixel grid.
    truth : Prediction
        Exact landing-point displacement of the tracer (ground truth), same grid.
    timings : dict
        Seconds spent rendering and predicting.
    """

    scene: Scene
    engine: str
    distorted: np.ndarray
    reference: np.ndarray | None
    model: Prediction
    truth: Prediction
    timings: dict = field(default_factory=dict)


def scaled_scene(scene: Scene, *, scale: float = 1.0, spp: int | None = None) -> Scene:
    """The scene with its image size scaled (same sensor, hence same field of view) and ``spp`` set.

    Parameters
    ----------
    scene : Scene
    scale : float
        Factor on both pixel counts (rounded to a multiple of 8 px); 1 keeps the scene's size.
    spp : int, optional
        Samples per pixel (default: the scene's).

    Returns
    -------
    Scene
    """
    if not np.isfinite(scale) or scale <= 0:
        raise InputError(f"the image scale must be a positive number, got {scale}")
    if spp is not None and int(spp) < 1:
        raise InputError(f"samples per pixel must be at least 1, got {spp}")
    changes: dict = {}
    if scale != 1.0:
        w, h = scene.camera.pixels
        pixels = [max(64, int(round(w * scale / 8.0)) * 8), max(64, int(round(h * scale / 8.0)) * 8)]
        changes["camera"] = {"pixels": pixels}
    if spp is not None:
        changes["render"] = {"samples_per_pixel": int(spp)}
    return scene.with_changes(**changes) if changes else scene


def render_inputs(
    scene: Scene,
    *,
    engine: str = "exact",
    reference: bool = True,
    progress: Callable[[str, int, int], None] | None = None,
) -> Inputs:
    """Render a scene and evaluate its model and exact truth on the camera pixel grid.

    Parameters
    ----------
    scene : Scene
    engine : {'exact', 'cycles'}
        Render engine (:func:`glassdist.render.get_renderer`); the truth always
        comes from the exact tracer's landing points.
    reference : bool
        Also render the glass-less image (needed by the Comparative Method and the figures).
    progress : callable(stage, done, total), optional

    Returns
    -------
    Inputs
    """
    eng = get_renderer(engine)

    def stage(name):
        return None if progress is None else (lambda done, total: progress(name, done, total))

    t0 = time.perf_counter()
    distorted = render_scene(scene, engine=eng, progress=stage(f"{scene.name}: render distorted"))
    ref = (render_scene(scene, engine=eng, reference=True, progress=stage(f"{scene.name}: render reference"))
           if reference else None)
    t1 = time.perf_counter()
    model = predict_displacement(scene)
    t2 = time.perf_counter()
    truth = exact_truth(scene, model)
    t3 = time.perf_counter()
    log.info("%s: rendered in %.1f s, model %.1f s, truth %.1f s", scene.name, t1 - t0, t2 - t1, t3 - t2)
    return Inputs(
        scene, getattr(eng, "name", engine), distorted, ref, model, truth,
        {"render_s": t1 - t0, "model_s": t2 - t1, "truth_s": t3 - t2},
    )


def evaluate(inputs: Inputs, *, method: str, params) -> Validation:
    """Analyse the rendered image and compare it with the model and the truth.

    Parameters
    ----------
    inputs : Inputs
    method : {'direct', 'comparative'}
    params : AnalyzerParams
        Analyzer parameters (N, sigma_mm, ...); the model and the truth go through
        the evaluation stack with the analyzer's resolved ``sigma_mm``,
        ``detrend_degree``, ``mm_per_px`` and valid region.

    Returns
    -------
    Validation
        ``metrics`` holds the ratios Analyzer/model, correlations, Procrustes
        rotation and scale, ``model_vs_exact`` and ``analyzer_vs_exact``;
        ``exact`` holds the truth's channels.
    """
    from ..analyzer import analyze

    if method not in ("direct", "comparative"):
        raise InputError(f"unknown method '{method}'; use 'direct' or 'comparative'")
    if method == "comparative" and inputs.reference is None:
        raise InputError("the Comparative Method needs the glass-less reference; render it (reference=True)")
    scene = inputs.scene
    t0 = time.perf_counter()
    result = analyze(
        inputs.distorted,
        pitch_mm=scene.backdrop.pitch_mm,
        distance_m=scene.backdrop.distance_m,
        reference=inputs.reference if method == "comparative" else None,
        params=params,
    )
    t1 = time.perf_counter()
    val = compare_with_scene(result, scene, model=inputs.model, truth=inputs.truth)
    val.metrics["analyze_s"] = t1 - t0
    log.info("%s %s: analysed in %.2f s, evaluated in %.2f s", scene.name, method, t1 - t0, time.perf_counter() - t1)
    return val


@dataclass(frozen=True)
class RunOptions:
    """How an experiment renders its scenes: the options every ``run_*`` function takes.

    Attributes
    ----------
    engine : {'exact', 'cycles'}
        Render engine of the images (the truth always comes from the exact tracer).
    scale : float
        Image size relative to the scenes' (1024 x 768 px); the field of view is kept.
    spp : int, optional
        Samples per pixel (default: the scenes', 16).
    progress : callable(stage, done, total), optional
        Called while rendering (when the scenes render in this process).
    executor : glassdist.distributed.Executor, optional
        Renders the scenes as parallel jobs (e.g. on a Dask cluster); default: here, in turn.
    """

    engine: str = "exact"
    scale: float = 1.0
    spp: int | None = None
    progress: Callable[[str, int, int], None] | None = None
    executor: object = None

    def prepare(self, scene: Scene) -> Scene:
        """The scene at this image scale and sample count (:func:`scaled_scene`)."""
        return scaled_scene(scene, scale=self.scale, spp=self.spp)

    def render(self, scene: Scene, *, reference: bool = True) -> Inputs:
        """Render a prepared scene and its predictions (:func:`render_inputs`)."""
        return render_inputs(scene, engine=self.engine, reference=reference, progress=self.progress)

    def render_each(self, scenes: list, *, reference: bool = True):
        """Render prepared scenes; yields ``(index, Inputs)`` in order here, as they finish on an executor.

        Raises the first render's exception.
        """
        if self.executor is None or not self.executor.distributed:
            for i, scene in enumerate(scenes):
                yield i, self.render(scene, reference=reference)
            return
        from functools import partial

        job = partial(render_inputs, engine=self.engine, reference=reference)
        for done in self.executor.as_completed(job, list(scenes)):
            if done.error is not None:
                raise done.error
            yield done.index, done.value


@dataclass(frozen=True)
class SceneRun:
    """One scene of an experiment: rendered once, analysed with each method.

    Attributes
    ----------
    scene : Scene
        The scene as rendered (scaled, samples per pixel set).
    inputs : Inputs
        Its renders, model and truth.
    params : AnalyzerParams
        Analyzer parameters of every method's run.
    validations : dict of str -> Validation
        Method -> the analyzer's run against model and truth (:func:`evaluate`).
    """

    scene: Scene
    inputs: Inputs
    params: object
    validations: dict

    def entry(self) -> dict:
        """The record keys every experiment writes for a scene: its name, seed and render timings."""
        return {"scene": self.scene.name, "seed": self.scene.render.seed, "timings": self.inputs.timings}


def run_scenes(
    scenes: dict,
    options: RunOptions,
    *,
    methods: tuple,
    reference: bool,
    detrend_degree: int,
    sigma_mm: float,
    params_file=None,
) -> dict:
    """Render each scene once and evaluate it with each method at one ``detrend_degree`` and ``sigma_mm``.

    Parameters
    ----------
    scenes : dict of str -> path
        Run name -> scene file.
    options : RunOptions
    methods : tuple of {'direct', 'comparative'}
    reference : bool
        Also render the glass-less image (the Comparative Method and the figures need it).
    detrend_degree : int
        Total degree N of the polynomial detrend.
    sigma_mm : float
        Reporting smoothing scale on the backdrop, mm.
    params_file : path, optional
        JSON file of analyzer parameters over each scene's own analysis settings
        (:func:`glassdist.theory.analysis_params`); ``detrend_degree`` and ``sigma_mm``, the
        experiment's own, stay over it. A bad file is bad input before anything renders.

    Returns
    -------
    dict of str -> SceneRun
        In the order of ``scenes``.
    """
    prepared = {name: options.prepare(load_scene(path)) for name, path in scenes.items()}
    file_params = None if params_file is None else read_params_file(params_file)  # read once, for every scene

    def params_of(scene):
        return analysis_params(scene, file_params, detrend_degree=detrend_degree, sigma_mm=sigma_mm)

    if file_params is not None:  # a bad file is bad input before anything renders
        params_of(next(iter(prepared.values())))
    names, runs = list(prepared), {}
    for i, inputs in options.render_each(list(prepared.values()), reference=reference):
        scene = prepared[names[i]]
        params = params_of(scene)
        runs[names[i]] = SceneRun(scene, inputs, params, {m: evaluate(inputs, method=m, params=params) for m in methods})
    return {name: runs[name] for name in names}


def common_region(runs: dict) -> np.ndarray:
    """The pixels compared in every validation of every run (bool, H x W)."""
    return np.logical_and.reduce([v.valid for run in runs.values() for v in run.validations.values()])


def settings_record(run: SceneRun, *, detrend_degree: int, sigma_mm: float, paper: dict) -> dict:
    """The record keys every experiment writes for its settings: engine, image size, spp, N, sigma, paper."""
    return {
        "engine": run.inputs.engine,
        "image_size": list(run.scene.camera.pixels),
        "samples_per_pixel": run.scene.render.samples_per_pixel,
        "detrend_degree": detrend_degree,
        "sigma_mm": float(sigma_mm),
        "paper": paper,
    }


def region_stats(field_mD: np.ndarray, region: np.ndarray) -> dict:
    """Mean |phi| and standard deviation of signed phi over a region (the paper's panel titles).

    Parameters
    ----------
    field_mD : ndarray (H, W)
        A channel, mD (NaN outside its valid region).
    region : ndarray of bool (H, W)

    Returns
    -------
    dict
        ``mean_abs`` and ``std`` (mD), ``pixels`` (count).
    """
    v = np.asarray(field_mD, float)[np.asarray(region, bool)]
    v = v[np.isfinite(v)]
    if v.size == 0:
        raise InputError("the region holds no finite value of the channel")
    return {"mean_abs": float(np.mean(np.abs(v))), "std": float(np.std(v)), "pixels": int(v.size)}


def relative_difference(a: float, b: float) -> float:
    """``|a - b| / max(|a|, |b|)`` (the paper's relative difference, §3.2)."""
    den = max(abs(a), abs(b))
    return float(abs(a - b) / den) if den > 0 else 0.0


def validation_record(val: Validation) -> dict:
    """JSON-serialisable summary of one analyzer run against model and truth."""
    res = val.analysis
    return {
        "method": res.method,
        "mm_per_px": float(res.mm_per_px),
        "sigma_mm": float(res.sigma_mm),
        "detrend_degree": int(res.detrend_degree),
        "analyzer_valid_fraction": float(res.valid.mean()),
        "demodulations": int(res.demodulations),  # 1: one pass; more where F5 ran
        "compared_fraction": float(val.valid.mean()),
        "ratios_vs_model": val.metrics["ratios"],
        "correlations_vs_model": val.metrics["correlations"],
        "procrustes_vs_model": val.metrics["procrustes"],
        "ratios_vs_exact": val.metrics["analyzer_vs_exact"],
        "model_vs_exact": val.metrics["model_vs_exact"],
        "statistics": {
            who: {SHORT[n]: region_stats(getattr(src, n), val.valid) for n in SHORT}
            for who, src in (("analyzer", res), ("model", val.analytical), ("exact", val.exact))
        },
        "warnings": list(res.warnings),
        "analyze_s": val.metrics.get("analyze_s"),
    }


def write_json(path: Path, record: dict) -> Path:
    """Write ``record`` (with the package version) as indented JSON."""
    path = Path(path)
    data = {"glassdist_version": __version__, **record}
    from ..io import to_jsonable

    path.write_text(json.dumps(to_jsonable(data), indent=2) + "\n", encoding="utf-8")
    return path


def share_fig_ax(fig=None, ax=None, *, nrows: int = 1, ncols: int = 1, figsize=(8, 6)):
    """Return ``(fig, axes)``: the given ones, or a new Agg figure with an ``nrows x ncols`` grid."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    if ax is not None:
        return (ax.figure if fig is None else fig), ax
    if fig is None:
        fig = plt.figure(figsize=figsize)
    axes = fig.subplots(nrows, ncols, squeeze=False)
    return fig, axes


def save_figure(fig, path: Path, *, dpi: int = 100) -> Path:
    """Save a figure to PNG and close it."""
    import matplotlib.pyplot as plt

    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return Path(path)


def map_panel(ax, fig, field_mD, region, *, vmin, vmax, cmap, title, label="mD"):
    """One heat map with its colour bar; NaN outside ``region``."""
    m = np.where(region, field_mD, np.nan)
    im = ax.imshow(m, cmap=cmap, vmin=vmin, vmax=vmax, interpolation="nearest")
    ax.set_title(title, fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.02, label=label)
    return im


def shared_limit(maps, regions, *, percentile: float = 99.5) -> float:
    """Colour limit shared by several panels: the largest ``percentile`` of |phi| among them."""
    lims = []
    for m, r in zip(maps, regions):
        v = np.abs(np.asarray(m, float)[np.asarray(r, bool)])
        v = v[np.isfinite(v)]
        if v.size:
            lims.append(float(np.percentile(v, percentile)))
    return max(lims) if lims and max(lims) > 0 else 1.0


@dataclass
class ExperimentResult:
    """What an experiment produced: its numbers, its markdown table and its figures.

    Attributes
    ----------
    name : str
        Experiment name (``parity``, ``pitch``, ``rotation``); output files are named after it.
    record : dict
        JSON-serialisable numbers, settings and bound checks.
    table : str
        Markdown table(s) of the headline numbers next to the paper's.
    figures : dict of str -> callable
        Output file name -> function returning ``(fig, axes)``.
    """

    name: str
    record: dict
    table: str
    figures: dict = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        """True when every bound in ``record['bounds']`` is met."""
        return all(b["met"] for b in self.record.get("bounds", {}).values())


def bound(value: float, limit: float, *, target: float = 0.0, paper: float | None = None, what: str = "") -> dict:
    """A bound check ``|value - target| <= limit`` recorded with the paper's value."""
    dev = abs(float(value) - target)
    return {
        "value": float(value),
        "target": float(target),
        "limit": float(limit),
        "deviation": dev,
        "met": bool(dev <= limit),
        "paper": paper,
        "what": what,
    }


def bounds_table(bounds: dict) -> str:
    """Markdown table of the bound checks."""
    rows = ["| check | ours | paper | bound | met |", "|---|---|---|---|---|"]
    for b in bounds.values():
        paper = "" if b["paper"] is None else f"{b['paper']:.3g}"
        tgt = f"{b['target']:g} ± {b['limit']:g}" if b["target"] else f"≤ {b['limit']:g}"
        rows.append(f"| {b['what']} | {b['value']:.4g} | {paper} | {tgt} | {'yes' if b['met'] else '**no**'} |")
    return "\n".join(rows)


def write_experiment(result: ExperimentResult, out: Path, *, command: str, dpi: int = 100) -> list[Path]:
    """Write ``<name>.json``, ``<name>.md`` and the figures of an experiment to ``out``.

    Parameters
    ----------
    result : ExperimentResult
    out : Path
        Existing output folder.
    command : str
        The command line that produced the outputs (recorded in the JSON and the markdown).

    Returns
    -------
    list of Path
        The files written.
    """
    out = Path(out)
    written = []
    record = {"experiment": result.name, "command": command, **result.record}
    written.append(write_json(out / f"{result.name}.json", record))
    for fname, make in result.figures.items():
        fig, _ = make()
        written.append(save_figure(fig, out / fname, dpi=dpi))
    figs = "\n".join(f"![{f}]({f})" for f in result.figures)
    md = (
        f"# Experiment: {result.name}\n\n"
        f"Produced by:\n\n```bash\n.venv/bin/{command}\n```\n\n"  # the environment's command (README Quick start)
        f"{result.table}\n\n"
        f"Numbers: [`{result.name}.json`]({result.name}.json) (glassdist {__version__}).\n\n{figs}\n"
    )
    p = out / f"{result.name}.md"
    p.write_text(md, encoding="utf-8")
    written.append(p)
    return written
