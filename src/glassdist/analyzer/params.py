"""Analyzer parameters: a validated, frozen model loaded from JSON.

Defaults are shipped in ``glassdist/data/analyzer_defaults.json`` (the same values
as the model's defaults); a user JSON file overrides any subset of them. Unknown
keys are errors, so a misspelt key never falls back silently to a default.
Every output records the resolved parameters (:meth:`AnalyzerParams.resolved`).

Lengths are in mm; scales expressed relative to the carrier are fractions of the
carrier period :math:`\\lambda_i^{px}` or of the carrier frequency :math:`|f_i|`.
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, Field, field_validator

from ..validation import MODEL_CONFIG, SIGMA_MM, load_mapping, safe_text, validate_model

# F5's photo passes with deformation_photo_passes 'auto' in the Comparative Method: the waves photo is
# explained at 0.9859 / 0.9871 / 0.9879 / 0.9885 after 3 / 4 / 5 / 6 (docs/transfer_function.md)
AUTO_PHOTO_PASSES = 6

__all__ = ["AnalyzerParams", "RECORDED_SETTINGS", "given_settings", "load_params", "default_params_path"]


def _auto_or_int(name: str, v, lo: int, hi: int):
    """``v`` unchanged if it is ``'auto'`` or an integer from ``lo`` to ``hi``; else the validation error saying so."""
    if v != "auto" and not lo <= int(v) <= hi:
        raise ValueError(f"{name} must be 'auto' or an integer from {lo} to {hi}")
    return v


class AnalyzerParams(BaseModel):
    """Algorithmic parameters of the Distortion Analyzer (paper §2.2).

    Physical inputs (pitch, distance L) are not parameters: they are arguments of
    :func:`glassdist.analyze`. ``sigma_mm`` and ``detrend_degree`` are here so that a
    specification can fix them in one file; the command line may override them.
    """

    model_config = MODEL_CONFIG

    pattern: Literal["auto", "lines", "checkerboard", "dots"] = Field(
        "auto",
        description="backdrop: 'lines' (crossed line grid, pitch = line spacing), "
        "'checkerboard' (pitch = square size; carriers along the diagonals, period pitch*sqrt(2)), "
        "'dots' (square lattice of dots, pitch = dot spacing; carriers along the lattice axes, period pitch) or "
        "'auto' (decided from the photo's spectrum: glassdist.analyzer.pattern)",
    )
    detrend_degree: int = Field(2, ge=0, le=8, description="A2: total degree N of the polynomial detrend")
    lens_model: Literal["none", "radial", "radial+center", "radial+tangential", "radial+tangential+center"] = Field(
        "radial",
        description="Block I (Direct): camera lens distortion fitted with the homography from the grid itself: "
        "'radial' (Brown k1, k2; the default), with 'tangential' p1, p2, with 'center' the principal point; "
        "'none' = pinhole. The fit is applied only where it stands out of the glass's own distortion and is "
        "global (refits without the inner disc or any quadrant agree), docs/lens_calibration.md",
    )
    sigma_mm: float | None = Field(
        None,
        ge=SIGMA_MM.lo,
        le=SIGMA_MM.hi,
        description="A2: metric-anchored smoothing scale on the backdrop, mm; "
        "None = sigma_periods carrier periods",
    )
    sigma_periods: float = Field(
        2.0, gt=0, le=1000, description="default smoothing scale in carrier periods, used when sigma_mm is None"
    )
    compensate_demodulation_blur: bool = Field(
        True,
        description="subtract (in quadrature) the blur Block F already applied from the A2 smoothing, "
        "so the total low-pass equals sigma_mm",
    )
    bandpass_sigma_along: float = Field(
        0.30, gt=0.05, le=0.6, description="F1: Gaussian bandpass width across the cross-term axis, fraction of |f_i|"
    )
    bandpass_sigma_cross: float = Field(
        0.22, gt=0.05, le=0.6,
        description="F1: Gaussian bandpass width towards the k1+k2 cross term (narrow axis), fraction of |f_other|",
    )
    isotropic_bandpass: bool = Field(False, description="ablation: use an isotropic bandpass of width bandpass_sigma_along")
    smoothing_periods: float = Field(1.0 / 3.0, gt=0, le=2.0, description="F3: complex smoothing sigma, carrier periods")
    min_period_px: float = Field(3.0, gt=2.0, le=1000, description="F1: shortest carrier period accepted, px")
    modulation_threshold: float = Field(
        0.3, gt=0, lt=1, description="valid region: local modulation / median modulation must exceed this"
    )
    local_modulation_threshold: float = Field(
        0.42, ge=0, lt=1,
        description="valid region: modulation / its local level (max over ~4 periods) must exceed this (frames, mullions)",
    )
    coherence_threshold: float = Field(
        0.5, ge=0, lt=1, description="valid region: phase coherence |G*z|/G*|z| of the smoothed signal must exceed this"
    )
    border_periods: float | None = Field(
        None, ge=0, le=100,
        description="valid region: margin around excluded areas (occluders, frames), carrier periods; "
        "null: derived from the demodulation kernel for margin_phase_error_periods",
    )
    edge_margin_periods: float | None = Field(
        None, ge=0, le=100,
        description="valid region: margin at the image edges, carrier periods (the periodic FFT mixes the opposite edge in); "
        "null: derived like border_periods",
    )
    margin_phase_error_periods: float = Field(
        0.1, gt=0, le=0.25,
        description="valid region: phase error (carrier periods) that an excluded area or the image edge may cause at the "
        "margin, worst case (an unrelated signal of equal amplitude behind the boundary)",
    )
    guard_band_sigmas: float = Field(
        1.5, ge=0, le=100,
        description="quality map: measured samples within this many reporting smoothing scales (sigma) of an excluded "
        "area or the image edge are reported but left out of statistics and specifications",
    )
    max_frequency_deviation: float = Field(
        0.5, gt=0, le=1.0,
        description="valid region: largest local offset of the grid frequency from the carrier, fraction of |f| "
        "(beyond it the bandpass attenuates or loses the signal: 'beyond measurable distortion'; at 0.5 the "
        "along-carrier bandpass passes a quarter of the amplitude)",
    )
    deformation_passes: int = Field(
        3, ge=0, le=8,
        description="F5: largest number of image-deformation passes once the measured region stops growing (a reference "
        "warped by the current displacement is synthesised and the photo's residual against it demodulated, so the "
        "bandpass sees the local grid at the carrier); 0 = one-pass demodulation",
    )
    deformation_growth_passes: int = Field(
        6, ge=0, le=16,
        description="F5: largest number of passes that may grow the measured region beyond the one-pass region, one "
        "carrier period per pass, into samples whose residual against the warped reference is small and coherent "
        "(strong local frequencies the one-pass bandpass clipped), never merging two of its parts; 0 = F5 stays "
        "within the one-pass region",
    )
    deformation_photo_passes: int | Literal["auto"] = Field(
        "auto",
        description="F5: largest number of passes, after the warped reference's, that deform the photo back to the "
        "reference's frame by the current displacement and demodulate it there, so that the bandpass passes the whole "
        "signal where the local frequency is far off the carrier; they start from the warped reference's field "
        "low-passed (deformation_photo_restart_periods); 0 = none. 'auto': 6 in the Comparative Method, 0 in the "
        "Direct Method, where Block I fits its baseline on F5's phases afterwards and, on ray-traced lenses whose "
        "baseline is weakly determined, moved with them (docs/transfer_function.md, 'Photo deformation')",
    )
    deformation_photo_restart_periods: float = Field(
        0.5, gt=0, le=5.0,
        description="F5: sigma of the Gaussian low-pass of the warped reference's field the photo passes start from, "
        "carrier periods (what that field carries beyond the filters' passband, no pass can see)",
    )
    deformation_min_deviation: float = Field(
        0.2, ge=0, le=1.0,
        description="F5: the passes run only where the one-pass local grid frequency departs from the carrier by more "
        "than this fraction of |f| (99th percentile, the demodulation's blur divided out; below it the one-pass "
        "demodulation is linear)",
    )
    deformation_max_deviation: float = Field(
        0.75, gt=0, le=1.5,
        description="F5: reach after image deformation, fraction of |f|: where the bandpass's gain at the local grid "
        "frequency is below its value this far off the carrier the sample is 'beyond measurable distortion'",
    )
    deformation_tolerance_periods: float = Field(
        0.002, gt=0, le=0.5,
        description="F5: the passes stop when the RMS update of the displacement is below this, carrier periods",
    )
    min_region_fraction: float = Field(
        0.01, ge=0, lt=1, description="valid region: drop connected regions smaller than this fraction of the image "
        "and than 2 x 2 carrier periods (analyzer.region.min_region_samples)")
    ransac_threshold_periods: float = Field(0.1, gt=0, le=10, description="I2: RANSAC inlier threshold, carrier periods")
    ransac_max_trials: int = Field(2000, ge=10, le=1_000_000)
    ransac_seed: int = Field(0, ge=0, le=2**32 - 1, description="I2: seed of the RANSAC sampler (results are reproducible)")
    a1_mode: Literal["projective", "isotropic"] = Field(
        "projective",
        description="A1: 'projective' differentiates with respect to backdrop mm through the local "
        "pixel->backdrop Jacobian; 'isotropic' uses the paper's single mm_per_px",
    )
    decimation: int | Literal["auto"] = Field(
        "auto", description="sampling step of the demodulated signals, px ('auto': about a third of the carrier period)"
    )

    analysis_block: Literal["auto", 1, 2, 4] = Field(
        "auto", description="Block A runs on m x m block means of the demodulation grid ('auto': as coarse as sigma and the "
        "demodulation's passband allow)"
    )

    @field_validator("deformation_photo_passes")
    @classmethod
    def _check_photo_passes(cls, v):
        return _auto_or_int("deformation_photo_passes", v, 0, 8)

    def photo_passes_for(self, comparative: bool) -> int:
        """The photo passes F5 may run: ``deformation_photo_passes``, its ``'auto'`` resolved by the method."""
        if self.deformation_photo_passes == "auto":
            return AUTO_PHOTO_PASSES if comparative else 0
        return int(self.deformation_photo_passes)

    @field_validator("decimation")
    @classmethod
    def _check_decimation(cls, v):
        return _auto_or_int("decimation", v, 1, 64)

    def resolved(self) -> dict:
        """The parameters as a JSON-serialisable dict (recorded in every output)."""
        return self.model_dump(mode="json")


def default_params_path() -> Path:
    """Path of the shipped defaults JSON (a template users can copy)."""
    return Path(str(resources.files("glassdist") / "data" / "analyzer_defaults.json"))


def load_params(source: str | os.PathLike[str] | dict | None = None, **overrides) -> AnalyzerParams:
    """Load and validate analyzer parameters.

    Parameters
    ----------
    source : path, dict or None
        JSON file (or already-parsed dict) overriding any subset of the defaults.
    **overrides
        Values that take precedence over the file (e.g. command-line options);
        ``None`` values are ignored.

    Returns
    -------
    AnalyzerParams

    Raises
    ------
    InputError
        Unreadable file, invalid JSON, unknown key or out-of-range value.

    Examples
    --------
    Defaults, overridden by a mapping (or a JSON file) and then by keywords:

    >>> from glassdist import load_params
    >>> params = load_params({"detrend_degree": 3, "sigma_mm": 20.0}, sigma_mm=40.0)
    >>> params.detrend_degree, params.sigma_mm
    (3, 40.0)
    >>> load_params({"sigma": 40.0})
    Traceback (most recent call last):
    ...
    glassdist.errors.InputError: ...sigma...
    """
    data: dict = {}
    label = "parameters"
    if isinstance(source, dict):
        data = dict(source)
    elif source is not None:
        label = f"'{safe_text(Path(source))}'"
        data = load_mapping(source, "parameter file", option="--params", fmt="json", expect="parameter: value pairs")
    data.update({k: v for k, v in overrides.items() if v is not None})
    return validate_model(AnalyzerParams, data, "parameters", label,
                          f"see {default_params_path().name} for the valid keys and defaults")


#: The analysis settings a run's record tells chosen from defaulted (its protocol's ``sources``).
RECORDED_SETTINGS = ("pattern", "detrend_degree", "sigma_mm", "sigma_periods")


def given_settings(params, *, pattern: str | None = None, fallback: AnalyzerParams | None = None) -> tuple[str, ...]:
    """Which of :data:`RECORDED_SETTINGS` a caller chose: set in ``params`` or, for the pattern, given as ``pattern``.

    Parameters
    ----------
    params : AnalyzerParams, dict, path or None
        As :func:`glassdist.analyze` takes it (an ``AnalyzerParams``' fields set, a mapping's
        or a file's keys).
    pattern : str, optional
        The ``pattern`` keyword; 'auto' (the photo decides) is not a choice.
    fallback : AnalyzerParams, optional
        The parameters used when ``params`` is None (a prepared reference's).
    """
    source = fallback if params is None else params
    if source is None:
        chosen = set()
    else:
        held = source if isinstance(source, AnalyzerParams) else load_params(source)
        chosen = {k for k in held.model_fields_set if not (k == "pattern" and held.pattern == "auto")}
    if pattern is not None and pattern != "auto":
        chosen.add("pattern")
    return tuple(k for k in RECORDED_SETTINGS if k in chosen)
