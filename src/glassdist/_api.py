"""Acceptance from Python: a specification's verdict on an analysis, and its full record.

:func:`evaluate_spec` is what ``glassdist analyze --spec`` prints, for a result in hand
(``glassdist.evaluate_spec``); the engine underneath is
:func:`glassdist.acceptance.assess.assess`. :func:`write_report` writes the record
(``report.html`` and the rest of the output folder) through the one output stage,
:func:`glassdist.storage.writer.write_outputs`. :func:`view` and :func:`compare` are
``glassdist view`` and ``glassdist compare`` on stored results
(:mod:`glassdist.viewpoint`).
"""

from __future__ import annotations

__all__ = ["compare", "evaluate_spec", "view", "write_report"]


def evaluate_spec(result, spec, *, mask=None, camera_distance_m=None):
    """The verdict of an acceptance specification on an analysis.

    Parameters
    ----------
    result : Result
        From :func:`glassdist.analyze`, or a run read back by :func:`glassdist.load_result`
        (any :class:`~glassdist.analyzer.result.Result`).
    spec : Spec, dict or path
        The specification (its JSON form as a dict, or the JSON file); see
        ``docs/user-guide/factory-acceptance.md``.
    mask : ndarray of bool (H, W), optional
        The region the analysis was asked for (``analyze(..., mask=)``): the coverage
        limit ``min_valid_percent`` is then checked against it, not the whole image.
    camera_distance_m : float, optional
        The camera-to-pane distance, m: needed by a specification's ``reference_geometry``
        (the capture converted to the geometry its limits hold at).

    Returns
    -------
    Verdict
        ``.passed``, ``.label`` (``"PASS"`` / ``"FAIL"``), ``.checks`` (one per protocol pin,
        coverage limit and criterion), ``.lines()`` as printed by the command line,
        ``.to_dict()`` as in ``summary.json``.

    Raises
    ------
    InputError
        Invalid specification, or a capture outside its protocol's capture limits
        (``min_px_per_period``).

    Notes
    -----
    Protocol pins are checks here (the analysis already ran): a result computed with
    another distance, pitch, smoothing scale or detrend degree than the specification
    pins fails them. Zones, per-zone statistics and worst regions are computed as in
    :func:`glassdist.acceptance.assess.assess`.

    Examples
    --------
    >>> import glassdist
    >>> from glassdist.synthetic import lens_displacement, synthetic_capture
    >>> cap = synthetic_capture((192, 256), pitch_mm=10.0, mm_per_px=1.25,
    ...                         displacement=lens_displacement(0.05, 2.0, radius_mm=40.0))
    >>> res = glassdist.analyze(cap.image, pitch_mm=10.0, distance_m=2.0, reference=cap.reference, sigma_mm=20.0)
    >>> spec = {"name": "demo", "protocol": {"distance_m": 2.0, "sigma_mm": 20.0},
    ...         "zones": [{"name": "vision", "inset_mm": 20}],
    ...         "criteria": [{"channel": "phi_eff", "statistic": "max_abs", "max_mD": 1000, "zone": "vision"}]}
    >>> v = glassdist.evaluate_spec(res, spec)
    >>> v.label, [c.passed for c in v.checks]
    ('PASS', [True, True, True])
    """
    from .acceptance.assess import assess

    return assess(result, spec, mask=mask, camera_distance_m=camera_distance_m).verdict


def write_report(result, out, *, spec=None, image=None, reference=None, mask=None, pane_id=None, site=None,
                 operator=None, lot=None, export=False, fields="analysis", history=None):
    """Write the self-contained HTML report of an analysis, with the rest of its output folder.

    Parameters
    ----------
    result : AnalysisResult
    out : path
        Output folder (created; an earlier glassdist run's files there are replaced).
    spec : Spec, dict or path, optional
        Acceptance specification: verdict, zones, worst regions over its limits.
    image, reference : path, optional
        The photo and glass-less reference files analysed: recorded with their SHA-256
        (the photo is drawn with the analysed region outlined).
    mask : path or ndarray of bool, optional
        The region the analysis was asked for: coverage is of it.
    pane_id, site, operator, lot : str, optional
        Stated in the report and ``summary.json``, and recorded in the history.
    export : bool
        Also ``fields.npz`` and ``tiff/``.
    fields : {'analysis', 'pixel'}
        Layout of ``result.npz``.
    history : glassdist.history.Recording or False, optional
        How the run is recorded in the results history (default: ``GLASSDIST_DB``, else
        the user's data folder; False: not recorded); see :func:`glassdist.write_outputs`.

    Returns
    -------
    pathlib.Path
        ``out/report.html``.

    Examples
    --------
    >>> import tempfile, pathlib, glassdist
    >>> from glassdist.synthetic import lens_displacement, synthetic_capture
    >>> cap = synthetic_capture((192, 256), pitch_mm=10.0, mm_per_px=1.25,
    ...                         displacement=lens_displacement(0.05, 2.0, radius_mm=40.0))
    >>> res = glassdist.analyze(cap.image, pitch_mm=10.0, distance_m=2.0, reference=cap.reference)
    >>> out = pathlib.Path(tempfile.mkdtemp()) / "pane"
    >>> glassdist.write_report(res, out, pane_id="P-1").name
    'report.html'
    """
    from pathlib import Path

    from .io import read_mask
    from .storage.writer import write_outputs

    mask_path = Path(mask) if isinstance(mask, (str, Path)) else None
    if mask_path is not None:
        mask = read_mask(mask_path, result.valid.shape)
    write_outputs(result, out, fields=fields, report=True, export=export, spec=spec, mask=mask,
                  metadata={"pane_id": pane_id, "lot": lot, "site": site, "operator": operator}, image_path=image,
                  reference_path=reference, mask_path=mask_path, history=history)
    return Path(out) / "report.html"


def _stored(result):
    from .storage import StoredResult, load_result

    return result if isinstance(result, StoredResult) else load_result(result)


def view(result, *, observer_distance_m, background_distance_m, viewing_angle_deg=0.0, viewing_azimuth_deg=0.0,
         sigma_mm=None, detrend_degree=None):
    """What ``analyze`` would report on a photo of the pane taken from another point (``glassdist view``).

    Parameters
    ----------
    result : str, Path or StoredResult
        The output folder of an analysis with ``camera_distance_m`` (``--camera-distance-m``), or
        :func:`load_result` of it.
    observer_distance_m, background_distance_m : float
        ``Do``, the observer to the pane centre along the line of sight, and ``Lo``, the pane to the
        backdrop seen through it, m.
    viewing_angle_deg, viewing_azimuth_deg : float
        ``theta`` (line of sight to the pane normal, below 70) and ``psi`` (0: the observer on the
        capture's image left, looking towards +x; 90: on its image top, looking towards +y).
    sigma_mm : float, optional
        The photo's smoothing on its backdrop, mm (default and least: the capture's carried there).
    detrend_degree : int, optional
        Default the capture's.

    Returns
    -------
    glassdist.viewpoint.ViewPrediction
        ``.statistics`` as ``analyze`` writes them, the maps on the photo's pixel grid, its
        ``.camera``, ``.factor`` and ``.warnings``.

    Examples
    --------
    >>> import glassdist
    >>> pred = glassdist.view("out/pane", observer_distance_m=10, background_distance_m=50,
    ...                       viewing_angle_deg=30)  # doctest: +SKIP
    >>> pred.statistics["phi_eff_mD"]["mean_abs"], pred.warnings  # doctest: +SKIP
    """
    from .viewpoint import predict_view

    return predict_view(_stored(result), observer_distance_m=observer_distance_m,
                        background_distance_m=background_distance_m, viewing_angle_deg=viewing_angle_deg,
                        viewing_azimuth_deg=viewing_azimuth_deg, sigma_mm=sigma_mm, detrend_degree=detrend_degree)


def compare(result_a, result_b):
    """Two captures of one pane on the intrinsic axis: their difference and its uncertainty (``glassdist compare``).

    Parameters
    ----------
    result_a, result_b : str, Path or StoredResult
        Output folders of two analyses with ``camera_distance_m`` (normal incidence, the camera
        aimed at the pane centre), or :func:`load_result` of them.

    Returns
    -------
    glassdist.viewpoint.Comparison
        ``.phi_eff_mean_abs``, ``.phi_shear_mean`` (each ``a``, ``b``, ``difference``,
        ``expanded_uncertainty``, ``consistent``), ``.consistent``, ``.to_dict()``.
    """
    from .viewpoint import compare_results

    return compare_results(_stored(result_a), _stored(result_b))
