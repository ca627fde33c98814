"""Acceptance from Python: a specification's verdict on an analysis, and its full record.

:func:`evaluate_spec` is what ``glassdist analyze --spec`` prints, for a result in hand
(``glassdist.evaluate_spec``); the engine underneath is
:func:`glassdist.report.acceptance.assess`.
"""

from __future__ import annotations

__all__ = ["evaluate_spec"]


def evaluate_spec(result, spec, *, mask=None):
    """The verdict of an acceptance specification on an analysis.

    Parameters
    ----------
    result : AnalysisResult
        From :func:`glassdist.analyze`.
    spec : Spec, dict or path
        The specification (its JSON form as a dict, or the JSON file); see
        ``docs/industrial_workflow.md``.
    mask : ndarray of bool (H, W), optional
        The region the analysis was asked for (``analyze(..., mask=)``): the coverage
        limit ``min_valid_percent`` is then checked against it, not the whole image.

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
    :func:`glassdist.report.acceptance.assess`.

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
    from .report.acceptance import assess
    from .report.spec import as_spec

    s, sha = as_spec(spec)
    path = "" if isinstance(spec, dict) or hasattr(spec, "criteria") else str(spec)
    return assess(result, s, spec_path=path, spec_sha256=sha, mask=mask).verdict
