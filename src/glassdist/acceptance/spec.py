"""Acceptance specifications: JSON criteria on the channel statistics, the protocol they were written for, zones.

A specification is a JSON object::

    {
      "name": "Line 2 acceptance, 6 mm float",
      "protocol": {"method": "comparative", "distance_m": 1.0, "pitch_mm": 5.0, "pattern": "checkerboard",
                   "sigma_periods": 2, "detrend_degree": 2, "min_px_per_period": 6},
      "pane": {"corners_frac": [[0.01, 0.015], [0.986, 0.01], [0.99, 0.95], [0.006, 0.955]], "size_mm": [1200, 900]},
      "zones": [{"name": "edge", "edge_band_mm": 50}, {"name": "vision", "inset_mm": 50}],
      "criteria": [
        {"channel": "phi_eff",   "statistic": "p95_abs",   "max_mD": 60, "zone": "vision"},
        {"channel": "phi_shear", "statistic": "max_abs",   "max_mD": 150},
        {"channel": "phi_eff",   "statistic": "area_over", "threshold_mD": 100, "max_percent": 1.0}
      ],
      "min_valid_percent": 50,
      "figures": {"colour_limit": "spec"},
      "worst_regions": {"max_count": 10}
    }

Criteria
--------
* ``statistic`` one of ``mean_abs``, ``std``, ``p95_abs``, ``max_abs`` (see
  :mod:`glassdist.acceptance.stats`) with ``max_mD``: passes when ``value <= max_mD``;
* ``statistic`` ``area_over`` with ``threshold_mD`` and ``max_percent``: passes when
  the percentage of the valid region where ``|phi| > threshold_mD`` is
  ``<= max_percent``.
* ``zone`` (optional): the statistic is taken over that zone's analysed pixels.
* ``channel`` ``phi_eff_sigma`` / ``phi_shear_sigma``: the same statistics of the
  per-pixel standard uncertainty (``phi_eff_sigma_mD``, ``phi_shear_sigma_mD``, from the
  image noise): e.g. ``{"channel": "phi_eff_sigma", "statistic": "p95_abs", "max_mD": 5}``
  requires a measurement precise enough for the limits it is judged against (a noisy
  capture then fails rather than passing or failing on noise).
* ``min_valid_percent`` (optional): the trusted area (quality label 0, the pixels every
  statistic covers; ``trusted_percent`` of ``summary.json``) must cover at least this
  percentage of the image (of the user's mask when one is given), so a pane cannot
  pass because little of it was measured; a zone's ``min_valid_percent`` is of the zone.
* ``protocol`` (optional, :class:`Protocol`): the capture and analysis the limits were
  written for. ``glassdist analyze`` takes each pinned value when its option is
  omitted and refuses an option that contradicts one (:func:`resolve_protocol`); a
  photo under ``min_px_per_period`` is refused (:func:`check_capture`). The verdict
  repeats each pin as a check (a result computed otherwise fails it).
* ``pane`` (optional, :class:`Pane`) and ``zones`` (optional, :class:`Zone`): named parts
  of the pane in pane millimetres (:mod:`glassdist.acceptance.zones`).
* ``figures`` (optional, :class:`Figures`) and ``worst_regions`` (optional,
  :class:`WorstRegions`): heatmap colour limit; worst-region threshold and count
  (:mod:`glassdist.acceptance.regions`).

A value that cannot be computed (empty valid region) fails its criterion. Unknown
keys are errors. Limits are in mD, percentages in percent of the valid region.

References
----------
Paper §4.1 (factory-line acceptance), §4.2 (contractual specification).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, Mapping

from pydantic import BaseModel, Field, field_validator, model_validator

from ..errors import InputError
from ..validation import MODEL_CONFIG, SIGMA_MM, carrier_period_mm, check_input_file, load_mapping, safe_text, validate_model
from .flatness_limits import WithFlatnessLimits
from .geometry import ReferenceGeometry, check_convertible
from .stats import format_limit, share_percent

if TYPE_CHECKING:
    import numpy as np

    from ..analyzer.params import AnalyzerParams
    from ..analyzer.result import Result

__all__ = ["Criterion", "Protocol", "Pane", "Zone", "WorstRegions", "Figures", "Spec", "Check", "Verdict", "ResolvedProtocol",
           "LoadedSpec", "load_spec", "as_spec", "spec_verdict", "spec_channels", "spec_limits", "resolve_protocol",
           "check_capture"]

_SYMBOL = {"phi_eff": "phi_eff", "phi_shear": "phi_shear", "phi_total": "phi_total",
           "phi_eff_sigma": "sigma(phi_eff)", "phi_shear_sigma": "sigma(phi_shear)"}
_STAT_TEXT = {"mean_abs": "mean |{c}|", "std": "std {c}", "p95_abs": "p95 |{c}|", "max_abs": "max |{c}|"}


class Criterion(BaseModel):
    """One acceptance criterion on one channel statistic."""

    model_config = MODEL_CONFIG

    channel: Literal["phi_eff", "phi_shear", "phi_total", "phi_eff_sigma", "phi_shear_sigma"]
    statistic: Literal["mean_abs", "std", "p95_abs", "max_abs", "area_over"]
    max_mD: float | None = Field(None, ge=0, le=1e6, description="upper limit of the statistic, mD")
    threshold_mD: float | None = Field(None, ge=0, le=1e6, description="area_over: pixel threshold on |phi|, mD")
    max_percent: float | None = Field(None, ge=0, le=100, description="area_over: largest allowed area, percent")
    label: str | None = Field(None, description="name printed in verdicts (default: built from the criterion)")
    zone: str | None = Field(None, description="name of a zone of the spec's 'zones' (default: the analysed region)")

    @model_validator(mode="after")
    def _check_limits(self) -> Criterion:
        if self.statistic == "area_over":
            if self.threshold_mD is None or self.max_percent is None or self.max_mD is not None:
                raise ValueError("an 'area_over' criterion needs 'threshold_mD' and 'max_percent' (and no 'max_mD')")
        elif self.max_mD is None or self.threshold_mD is not None or self.max_percent is not None:
            raise ValueError(f"a '{self.statistic}' criterion needs 'max_mD' (and no 'threshold_mD'/'max_percent')")
        return self

    @property
    def stat_key(self) -> str:
        """Key of the statistic in :func:`glassdist.acceptance.stats.acceptance_statistics`'s dict."""
        return format_limit(self.threshold_mD or 0.0) if self.statistic == "area_over" else str(self.statistic)

    def describe(self) -> str:
        """Text of the criterion, e.g. ``p95 |phi_eff| <= 60 mD``."""
        if self.label:
            return self.label
        c = _SYMBOL[self.channel]
        where = f" in zone '{self.zone}'" if self.zone else ""
        if self.statistic == "area_over":
            return f"area |{c}| > {self.threshold_mD:g} mD <= {self.max_percent:g} %{where}"
        return f"{_STAT_TEXT[self.statistic].format(c=c)}{where} <= {self.max_mD:g} mD"


class Protocol(BaseModel):
    """Capture and analysis settings a specification's limits were written for (each optional).

    Pinned values are taken by ``glassdist analyze --spec`` when the matching option is
    omitted; an option that contradicts one is a bad input (exit 2), see
    :func:`resolve_protocol`. ``min_px_per_period`` is a capture limit: a photo whose grid
    carrier period is shorter is refused (exit 2), since a verdict on a capture outside
    the protocol would not be one on the glass.
    """

    model_config = MODEL_CONFIG

    method: Literal["comparative", "direct"] | None = None
    distance_m: float | None = Field(None, gt=0, allow_inf_nan=False, description="glass-to-grid distance L, m")
    pitch_mm: float | None = Field(None, gt=0, allow_inf_nan=False, description="printed grid pitch, mm")
    pattern: Literal["lines", "checkerboard", "dots"] | None = None
    sigma_mm: float | None = Field(None, gt=0, le=SIGMA_MM.hi, allow_inf_nan=False, description="smoothing scale, mm")
    sigma_periods: float | None = Field(None, gt=0, allow_inf_nan=False,
                                        description="smoothing scale, carrier periods (instead of sigma_mm)")
    detrend_degree: int | None = Field(None, ge=0, le=8)
    min_px_per_period: float | None = Field(
        None, gt=0, allow_inf_nan=False,
        description="capture limit: shortest carrier period in the photo, px (pitch for lines, pitch*sqrt(2) "
                    "for checkerboards)")
    optics: Literal["transmission", "reflection"] | None = Field(
        None, description="transmission (grid seen through the pane) or reflection (grid board seen in it); "
                          "in reflection distance_m is the board-to-pane distance D")
    camera_distance_m: float | None = Field(None, gt=0, allow_inf_nan=False,
                                            description="reflection: camera-to-pane distance C, m")
    incidence_deg: float | None = Field(None, ge=0, lt=80, allow_inf_nan=False,
                                        description="reflection: angle of incidence at the view's centre, deg")
    lens_calibration: Literal["photo", "file", "photo_or_file"] | None = Field(
        None, description="Direct Method: the camera lens must come from a calibration photo (--lens-photo), a "
                          "camera file (--camera-file) or either, not from the photo alone")

    @model_validator(mode="after")
    def _one_sigma(self) -> Protocol:
        if self.sigma_mm is not None and self.sigma_periods is not None:
            raise ValueError("give 'sigma_mm' or 'sigma_periods', not both")
        return self


_NAME_RE = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"


class Pane(BaseModel):
    """The pane's outline in the photograph: four corners and the pane's size (mm).

    The corners are ``[x, y]`` (x along columns, y down the rows) in the order top-left,
    top-right, bottom-right, bottom-left of the pane as seen; the pane frame's origin is the
    top-left corner, x along the top edge, y along the left edge. Give them in exactly one
    of two forms:

    * ``corners_frac``: fractions of the image, ``[0, 0]`` the photo's top-left corner (the
      outer edge of its first pixel) and ``[1, 1]`` its bottom-right one. The same file then
      serves every resolution of the same set-up (camera, framing, pane): a corner lands at
      ``x_px = fx * W - 0.5``, ``y_px = fy * H - 0.5`` of a ``W x H`` photo (pixel centres at
      integer coordinates). ``[[0, 0], [1, 0], [1, 1], [0, 1]]``: the pane fills the photo.
    * ``corners_px``: pixels of the photo the specification was written for (centres at
      integer coordinates); valid for that resolution only.

    Either way the corners are checked against each photo judged
    (:func:`glassdist.acceptance.zones.check_pane`): they must lie inside it, and their span
    in backdrop millimetres by the measured scale (``mm_per_px``) must agree with
    ``size_mm`` for the capture geometry, or the run is refused (exit 2) rather than judging
    a part of the photo that is not the pane.
    """

    model_config = MODEL_CONFIG

    corners_px: tuple[tuple[float, float], tuple[float, float], tuple[float, float], tuple[float, float]] | None = None
    corners_frac: tuple[tuple[float, float], tuple[float, float], tuple[float, float], tuple[float, float]] | None = (
        Field(None, description="corners as fractions of the image's width and height, 0 to 1"))
    size_mm: tuple[float, float]

    @model_validator(mode="after")
    def _check(self) -> Pane:
        import numpy as np

        if not all(np.isfinite(v) and v > 0 for v in self.size_mm):
            raise ValueError("'size_mm' must be two positive numbers [width, height]")
        if (self.corners_px is None) == (self.corners_frac is None):
            raise ValueError("give the corners as 'corners_frac' (fractions of the image, any resolution) or "
                             "'corners_px' (pixels of one resolution), exactly one of them")
        key = "corners_px" if self.corners_px is not None else "corners_frac"
        c = np.asarray(getattr(self, key), dtype=float)
        if not np.all(np.isfinite(c)):
            raise ValueError(f"'{key}' must be finite numbers")
        if key == "corners_frac" and not np.all((c >= 0) & (c <= 1)):
            raise ValueError("'corners_frac' must lie between 0 and 1 (fractions of the image's width and height)")
        # a convex quadrilateral in the stated order: every turn has the same sign
        d = np.roll(c, -1, axis=0) - c
        turns = d[:, 0] * np.roll(d, -1, axis=0)[:, 1] - d[:, 1] * np.roll(d, -1, axis=0)[:, 0]
        if not (np.all(turns > 0) or np.all(turns < 0)):
            raise ValueError(f"'{key}' must be a convex quadrilateral: top-left, top-right, bottom-right, "
                             "bottom-left")
        return self

    @property
    def corners_key(self) -> str:
        """``"corners_frac"`` or ``"corners_px"``: the form the corners were given in."""
        return "corners_px" if self.corners_px is not None else "corners_frac"

    def corners_in(self, shape: tuple[int, ...]) -> np.ndarray:
        """The corners on a photo of ``shape`` ``(H, W)``, px (array (4, 2) of ``x, y``, pixel centres at integers)."""
        import numpy as np

        if self.corners_px is not None:
            return np.asarray(self.corners_px, dtype=np.float64)
        c = np.asarray(self.corners_frac, dtype=np.float64)
        return c * np.array([shape[1], shape[0]], dtype=np.float64) - 0.5


class Zone(BaseModel):
    """A named part of the pane, in pane millimetres (exactly one shape key).

    * ``edge_band_mm``: the band of this width along the pane outline;
    * ``inset_mm``: the pane minus a border of this width (0: the whole pane);
    * ``polygon_mm``: a polygon ``[[x, y], ...]`` in the pane frame (mm).

    ``min_valid_percent`` (optional): the trusted area must cover at least this
    share of the zone (its ``trusted_percent``).
    """

    model_config = MODEL_CONFIG

    name: str = Field(..., pattern=_NAME_RE, description="letters, digits, '_', '.', '-'")
    edge_band_mm: float | None = Field(None, gt=0, allow_inf_nan=False)
    inset_mm: float | None = Field(None, ge=0, allow_inf_nan=False)
    polygon_mm: tuple[tuple[float, float], ...] | None = Field(None, min_length=3)
    min_valid_percent: float | None = Field(None, ge=0, le=100)

    @model_validator(mode="after")
    def _one_shape(self) -> Zone:
        given = [k for k in ("edge_band_mm", "inset_mm", "polygon_mm") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(f"zone '{self.name}' needs exactly one of 'edge_band_mm', 'inset_mm', 'polygon_mm'")
        if self.polygon_mm is not None:
            import numpy as np

            if not np.all(np.isfinite(np.asarray(self.polygon_mm, dtype=float))):
                raise ValueError(f"zone '{self.name}': 'polygon_mm' must be finite numbers")
        return self

    def describe(self) -> str:
        """Text of the zone's definition, e.g. ``band 50 mm along the pane outline``."""
        if self.edge_band_mm is not None:
            return f"band {self.edge_band_mm:g} mm along the pane outline"
        if self.inset_mm is not None:
            return f"pane minus a {self.inset_mm:g} mm border"
        return f"polygon of {len(self.polygon_mm or ())} vertices (pane mm)"


class WorstRegions(BaseModel):
    """Settings of the worst-region list (see :mod:`glassdist.acceptance.regions`)."""

    model_config = MODEL_CONFIG

    threshold_mD: dict[Literal["phi_eff", "phi_shear", "phi_total"], float] = Field(
        default_factory=dict, description="per channel threshold on |phi|, mD (default: the spec's limit)")
    max_count: int = Field(10, ge=1, le=1000)
    min_area_mm2: float = Field(0.0, ge=0, allow_inf_nan=False)


class Figures(BaseModel):
    """How the heatmaps are drawn.

    ``colour_limit``: ``"auto"`` (default: the 99th percentile of ``|phi|``, shared by the
    two channels), ``"spec"`` (each channel's colour scale ends at its smallest limit in
    the specification, so every pixel over the limit shows in the top colour), or a
    number in mD.
    """

    model_config = MODEL_CONFIG

    colour_limit: Literal["auto", "spec"] | float = "auto"

    @field_validator("colour_limit")
    @classmethod
    def _positive(cls, v: str | float) -> str | float:
        if not isinstance(v, str) and not (math.isfinite(v) and v > 0):
            raise ValueError("'colour_limit' must be 'auto', 'spec' or a positive number of mD")
        return v


class Spec(WithFlatnessLimits):
    """An acceptance specification (see the module docstring for the JSON form; ``flatness``: its base's)."""

    model_config = MODEL_CONFIG

    name: str = Field(..., min_length=1)
    description: str = ""
    criteria: tuple[Criterion, ...] = ()  # with 'flatness', at least one entry (WithFlatnessLimits)
    min_valid_percent: float | None = Field(None, ge=0, le=100)
    protocol: Protocol = Protocol()
    pane: Pane | None = None
    zones: tuple[Zone, ...] = ()
    reference_geometry: ReferenceGeometry | None = None
    worst_regions: WorstRegions = WorstRegions()
    figures: Figures = Figures()

    @model_validator(mode="after")
    def _check_zones(self) -> Spec:
        names = [z.name for z in self.zones]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"zone name(s) {', '.join(dup)} given twice; give each zone its own 'name'")
        for c in self.criteria:
            if c.zone is not None and c.zone not in names:
                known = ", ".join(names) or "none defined"
                raise ValueError(f"a criterion names zone '{c.zone}', which is not in 'zones' ({known})")
        check_convertible(self.reference_geometry, self.criteria)
        return self

    def zone(self, name: str) -> Zone:
        """The :class:`Zone` called ``name``."""
        return next(z for z in self.zones if z.name == name)


@dataclass(frozen=True)
class Check:
    """Outcome of one criterion: ``value`` compared with ``limit`` (``value <= limit`` or ``>=``).

    ``covers_percent`` and ``covers``: for a criterion on the channels, the trusted share
    (percent) of the part it judges (``"zone 'vision'"``, ``"the image"`` or ``"the mask"``):
    what the value speaks for; the rest of that part was not judged. None for the protocol
    and coverage checks.
    """

    criterion: str
    value: float | str | None
    limit: float | str
    unit: str
    comparison: str
    passed: bool
    note: str = ""
    covers_percent: float | None = None
    covers: str = ""

    def line(self) -> str:
        """One line for the console.

        For example ``PASS  p95 |phi_eff| <= 60 mD  (value 41.2 mD; over the trusted 71.97 % of zone 'vision')``.
        """
        if isinstance(self.value, float):
            value = "not computable" if math.isnan(self.value) else f"{self.value:.4g} {self.unit}".rstrip()
        else:
            value = str(self.value)
        tail = ""
        if self.covers_percent is not None:
            share = "none" if math.isnan(self.covers_percent) else f"the trusted {self.covers_percent:.4g} %"
            tail = f"; over {share} of {self.covers}"
        tail += f"; {self.note}" if self.note else ""
        return f"{'PASS' if self.passed else 'FAIL'}  {safe_text(self.criterion)}  (value {safe_text(value)}{safe_text(tail)})"


@dataclass(frozen=True)
class Verdict:
    """Result of a specification on one analysis."""

    spec_name: str
    spec_path: str
    spec_sha256: str
    checks: tuple[Check, ...]

    @property
    def passed(self) -> bool:
        """True when every check passed."""
        return all(c.passed for c in self.checks)

    @property
    def label(self) -> str:
        """``"PASS"`` or ``"FAIL"``."""
        return "PASS" if self.passed else "FAIL"

    def lines(self) -> list[str]:
        """Console lines: one per check, then ``VERDICT: PASS|FAIL (n/m criteria passed) spec '<name>'``."""
        n_ok = sum(c.passed for c in self.checks)
        return [c.line() for c in self.checks] + [
            f"VERDICT: {self.label} ({n_ok}/{len(self.checks)} criteria passed) spec '{safe_text(self.spec_name)}'"
        ]

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable form (NaN values become ``null``)."""
        checks = []
        for c in self.checks:
            d = asdict(c)
            for k in ("value", "covers_percent"):
                if isinstance(d[k], float) and math.isnan(d[k]):
                    d[k] = None
            checks.append(d)
        return {
            "result": self.label, "passed": self.passed, "spec_name": self.spec_name,
            "spec_path": self.spec_path, "spec_sha256": self.spec_sha256, "checks": checks,
        }


@dataclass(frozen=True)
class LoadedSpec:
    """A specification as one run uses it: the model, the file it came from and what is derived from it, once.

    Attributes
    ----------
    spec : Spec
    sha256 : str
        SHA-256 of the file's bytes as read (``""`` for a Spec or a dict given in Python);
        recorded with every verdict.
    path : str
        The file (``""`` when none).
    limits : dict
        :func:`spec_limits`: ``{channel: sorted limits, mD}`` (one threshold mask each).
    """

    spec: Spec
    sha256: str = ""
    path: str = ""
    limits: dict[str, list[float]] = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "limits", spec_limits(self.spec))  # derived once, from the model

    @property
    def label(self) -> str:
        """How messages name it: ``the specification 'PATH'`` (or ``the specification``)."""
        return f"the specification '{self.path}'" if self.path else "the specification"


def load_spec(path: str | Path) -> LoadedSpec:
    """Read and validate a specification JSON file (read once: its SHA-256 is of the bytes parsed).

    Parameters
    ----------
    path : path
        JSON file (a top-level ``"$comment"`` key is allowed and ignored).

    Returns
    -------
    LoadedSpec
        ``.spec``, ``.sha256`` (recorded with every verdict), ``.path``, ``.limits``.

    Raises
    ------
    InputError
        Missing file, invalid JSON, unknown key, missing or out-of-range limit.
    """
    p = check_input_file(path, "specification file", option="--spec")
    digest = hashlib.sha256()
    data = load_mapping(p, "specification file", option="--spec", fmt="json", expect="'name' and 'criteria'",
                        digest=digest)
    spec = validate_model(Spec, data, "specification", f"'{safe_text(p)}'",
                          "see docs/user-guide/factory-acceptance.md for the format")
    return LoadedSpec(spec, digest.hexdigest(), str(path))


def as_spec(spec: LoadedSpec | Spec | Mapping[str, Any] | str | Path) -> LoadedSpec:
    """A :class:`LoadedSpec` from a LoadedSpec, a Spec, a dict of its JSON form, or a JSON file.

    Raises
    ------
    InputError
        Invalid specification (one line).
    """
    if isinstance(spec, LoadedSpec):
        return spec
    if isinstance(spec, Spec):
        return LoadedSpec(spec)
    if isinstance(spec, Mapping):
        data = {k: v for k, v in spec.items() if k != "$comment"}
        return LoadedSpec(validate_model(Spec, data, "specification", "the given mapping",
                                         "see docs/user-guide/factory-acceptance.md for the format"))
    return load_spec(spec)


def spec_channels(spec: Spec) -> tuple[str, ...]:
    """Channels the criteria of ``spec`` judge (those of :data:`glassdist.acceptance.stats.STATISTIC_FIELDS`), in order."""
    return tuple(dict.fromkeys(c.channel for c in spec.criteria))


def spec_limits(spec: Spec) -> dict[str, list[float]]:
    """Thresholds per channel (mD) a spec draws masks and area statistics for.

    Returns
    -------
    dict
        ``{channel: sorted list of limits}``, the ``threshold_mD`` of area criteria
        and the ``max_mD`` of the ``max_abs`` / ``p95_abs`` criteria.
    """
    out: dict[str, set[float]] = {}
    for c in spec.criteria:
        lim = c.threshold_mD if c.statistic == "area_over" else c.max_mD
        if c.statistic in ("area_over", "max_abs", "p95_abs") and lim is not None:
            out.setdefault(c.channel, set()).add(float(lim))
    return {k: sorted(v) for k, v in out.items()}


_OPTION = {"pitch_mm": "--pitch-mm", "distance_m": "--distance-m", "pattern": "--pattern", "sigma_mm": "--sigma-mm",
           "detrend_degree": "--detrend-degree"}
_UNIT = {"pitch_mm": " mm", "distance_m": " m", "sigma_mm": " mm", "sigma_periods": " periods"}


def _text(v: object) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float) or isinstance(b, float):
        return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-12)
    return bool(a == b)


@dataclass(frozen=True)
class ResolvedProtocol:
    """The settings of one analysis after a specification's protocol was applied.

    Attributes
    ----------
    method : {'comparative', 'direct'}
    pitch_mm, distance_m : float
        Physical inputs (mm, m).
    pattern : {'lines', 'checkerboard', 'dots'}
    detrend_degree : int
    sigma_mm : float
        Smoothing scale (mm) the analysis will use.
    params_overrides : dict
        Values to pass to :func:`glassdist.analyzer.load_params` as overrides
        (``pattern``, ``detrend_degree``, ``sigma_mm`` or ``sigma_periods``).
    pinned : dict
        The specification's protocol as written (``None`` entries left out).
    sources : dict
        For each resolved setting, where it came from: ``"option"``, ``"spec"``,
        ``"params"`` or ``"default"``.
    """

    method: str
    pitch_mm: float
    distance_m: float
    pattern: str
    detrend_degree: int
    sigma_mm: float
    params_overrides: dict[str, Any]
    pinned: dict[str, Any]
    sources: dict[str, str]

    def to_dict(self) -> dict[str, Any]:
        """JSON form recorded in ``summary.json`` under ``"protocol"``."""
        return {
            "pinned": dict(self.pinned),
            "resolved": {"method": self.method, "pitch_mm": self.pitch_mm, "distance_m": self.distance_m,
                         "pattern": self.pattern, "detrend_degree": self.detrend_degree, "sigma_mm": self.sigma_mm},
            "sources": dict(self.sources),
        }


def resolve_protocol(protocol: Protocol | None = None, *, reference_given: bool, pitch_mm: float | None = None,
                     distance_m: float | None = None, pattern: str | None = None, sigma_mm: float | None = None,
                     detrend_degree: int | None = None, params: AnalyzerParams | None = None,
                     spec_label: str = "the specification") -> ResolvedProtocol:
    """Merge the analysis options with a specification's pinned protocol.

    An omitted option takes the pinned value; an option (or a value set in the
    ``--params`` file) that differs from a pinned value is refused, so that a pane
    is never judged against limits written for another capture or analysis.

    Parameters
    ----------
    protocol : Protocol, optional
        The specification's protocol (None: nothing pinned).
    reference_given : bool
        True when a glass-less reference photo is given (Comparative method).
    pitch_mm, distance_m : float, optional
        Grid pitch (mm) and glass-to-grid distance L (m) from the options.
    pattern, sigma_mm, detrend_degree : optional
        The options' values (None: omitted).
    params : AnalyzerParams, optional
        Parameters read from the ``--params`` file alone (no overrides): the values it
        sets explicitly are checked against the pins too.
    spec_label : str
        How errors name the specification (e.g. its path).

    Returns
    -------
    ResolvedProtocol

    Raises
    ------
    InputError
        An option contradicts the protocol, the method does not match it, or the pitch
        or distance is given by neither.

    Examples
    --------
    >>> p = Protocol(distance_m=1.0, pitch_mm=5.0, sigma_periods=2.0, pattern="checkerboard")
    >>> r = resolve_protocol(p, reference_given=True)
    >>> r.distance_m, r.sources["distance_m"], round(r.sigma_mm, 3)
    (1.0, 'spec', 14.142)
    >>> resolve_protocol(p, reference_given=True, distance_m=3.0)
    Traceback (most recent call last):
    ...
    glassdist.errors.InputError: --distance-m 3 contradicts the protocol of the specification (distance_m = 1 m);
    leave --distance-m out to use the specification's value, or use a specification written for this setting
    """
    protocol = protocol or Protocol()
    pinned = protocol.model_dump(exclude_none=True)
    method = _checked_method(protocol, reference_given, spec_label)
    given = {"pitch_mm": pitch_mm, "distance_m": distance_m, "pattern": pattern, "sigma_mm": sigma_mm,
             "detrend_degree": detrend_degree}
    from_file = _file_settings(params)
    values, sources = _merged_settings(given, pinned, from_file, spec_label)
    p_c = carrier_period_mm(float(values["pitch_mm"]), values["pattern"])
    overrides = {k: values[k] for k in ("pattern", "detrend_degree") if sources[k] != "default"}
    values["sigma_mm"], sources["sigma_mm"], passed_on = _sigma_setting(protocol, values, sources, from_file, params,
                                                                        p_c, spec_label)
    if passed_on:
        overrides["sigma_mm"] = values["sigma_mm"]
    return ResolvedProtocol(method, float(values["pitch_mm"]), float(values["distance_m"]), values["pattern"],
                            int(values["detrend_degree"]), float(values["sigma_mm"]), overrides, pinned,
                            {"method": "spec" if protocol.method else "option", "pitch_mm": sources["pitch_mm"],
                             "distance_m": sources["distance_m"], "pattern": sources["pattern"],
                             "detrend_degree": sources["detrend_degree"], "sigma_mm": sources["sigma_mm"]})


def _checked_method(protocol: Protocol, reference_given: bool, spec_label: str) -> str:
    """The analysis method the inputs give (``'comparative'`` with a reference), refused when the protocol pins the other."""
    method = "comparative" if reference_given else "direct"
    if protocol.method is not None and protocol.method != method:
        fix = "give --reference REF (the glass-less photo)" if protocol.method == "comparative" else "leave --reference out"
        raise InputError(f"the protocol of {spec_label} requires the {protocol.method} method; {fix}")
    return method


def _file_settings(params: AnalyzerParams | None) -> dict[str, Any]:
    """The settings a ``--params`` file sets explicitly (``pattern``, ``sigma_mm``, ``sigma_periods``, ``detrend_degree``)."""
    from_file: dict[str, Any] = {}
    if params is not None:
        from_file = {k: getattr(params, k) for k in ("pattern", "sigma_mm", "sigma_periods", "detrend_degree")
                     if k in params.model_fields_set}
    return from_file


def _merged_settings(given: dict[str, Any], pinned: dict[str, Any], from_file: dict[str, Any], spec_label: str
                     ) -> tuple[dict[str, Any], dict[str, str]]:
    """Each option's value from the option, else the pin, else the parameter file, else the default.

    Parameters
    ----------
    given : dict
        The options' values (None: omitted), by setting name.
    pinned : dict
        The protocol as written.
    from_file : dict
        As returned by :func:`_file_settings`.
    spec_label : str
        How errors name the specification.

    Returns
    -------
    values, sources : dict
        The settings known so far (``sigma_mm`` only when given or set in the file) and
        where each came from.

    Raises
    ------
    InputError
        An option or the file contradicts a pin, or the pitch or distance is given by neither.
    """
    values, sources = {}, {}
    for key, opt in _OPTION.items():
        pin = pinned.get(key)
        if given[key] is not None:
            if pin is not None and not _same(given[key], pin):
                raise InputError(
                    f"{opt} {_text(given[key])} contradicts the protocol of {spec_label} ({key} = {_text(pin)}"
                    f"{_UNIT.get(key, '')}); leave {opt} out to use the specification's value, or use a specification "
                    "written for this setting")
            values[key], sources[key] = given[key], "option"
        elif pin is not None:
            values[key], sources[key] = pin, "spec"
        elif key in from_file and from_file[key] is not None:
            values[key], sources[key] = from_file[key], "params"
    for key in ("pattern", "sigma_mm", "detrend_degree"):
        if pinned.get(key) is not None and key in from_file and not _same(from_file[key], pinned[key]):
            raise InputError(f"the --params file sets {key} = {from_file[key]} but the protocol of {spec_label} pins "
                             f"{key} = {pinned[key]}; remove '{key}' from the parameter file")
    for key in ("pitch_mm", "distance_m"):
        if key not in values:
            what = "the grid pitch, mm" if key == "pitch_mm" else "the glass-to-grid distance L, m"
            raise InputError(f"{_OPTION[key]} is required ({what}), or a --spec whose protocol pins {key}")
    values.setdefault("pattern", "lines")
    sources.setdefault("pattern", "default")
    values.setdefault("detrend_degree", 2)
    sources.setdefault("detrend_degree", "default")
    return values, sources


def _sigma_setting(protocol: Protocol, values: dict[str, Any], sources: dict[str, str], from_file: dict[str, Any],
                   params: AnalyzerParams | None, p_c: float, spec_label: str) -> tuple[float, str, bool]:
    """The smoothing scale: the protocol's ``sigma_periods`` carrier periods, else the option's or the file's.

    Parameters
    ----------
    protocol : Protocol
    values, sources : dict
        As returned by :func:`_merged_settings`.
    from_file : dict
        As returned by :func:`_file_settings`.
    params : AnalyzerParams or None
        The ``--params`` file's parameters.
    p_c : float
        Carrier period, mm.
    spec_label : str
        How errors name the specification.

    Returns
    -------
    sigma_mm : float
    source : str
    passed_on : bool
        Whether the value goes to the analysis as an override (otherwise the parameters'
        own ``sigma_periods`` gives it).
    """
    if protocol.sigma_periods is not None:
        want = protocol.sigma_periods * p_c
        have = values.get("sigma_mm")
        if have is not None and not _same(float(have), want):
            via = "--sigma-mm" if sources["sigma_mm"] == "option" else "the --params file's sigma_mm"
            raise InputError(f"{via} {have:g} contradicts the protocol of {spec_label} (sigma_periods = "
                             f"{protocol.sigma_periods:g}, i.e. {want:.4g} mm at this pitch and pattern); leave it out "
                             "to use the specification's value")
        return want, "spec", True
    if "sigma_mm" in values:
        return values["sigma_mm"], sources["sigma_mm"], True
    periods = from_file.get("sigma_periods", 2.0) if params is not None else 2.0
    return periods * p_c, ("params" if "sigma_periods" in from_file else "default"), False


def check_lens_source(protocol: Protocol | None, *, lens_photo: bool, camera_file: bool,
                      spec_label: str = "the specification") -> None:
    """Refuse a run without the lens calibration source the protocol requires (``lens_calibration``).

    Raises
    ------
    InputError
        The protocol requires a calibration photo or a camera file that was not given.
    """
    want = None if protocol is None else protocol.lens_calibration
    if want is None:
        return
    ok = {"photo": lens_photo, "file": camera_file, "photo_or_file": lens_photo or camera_file}[want]
    if not ok:
        need = {"photo": "--lens-photo PHOTO", "file": "--camera-file FILE",
                "photo_or_file": "--lens-photo PHOTO or --camera-file FILE"}[want]
        raise InputError(f"the protocol of {spec_label} requires the camera lens calibrated beforehand "
                         f"(lens_calibration = {want}); give {need}")


def check_capture(protocol: Protocol | None, result: Result, *, spec_label: str = "the specification") -> None:
    """Refuse a capture outside the protocol's capture limits.

    Raises
    ------
    InputError
        The photo's carrier period is shorter than ``min_px_per_period`` px: the pane
        is not judged (exit 2), the photo must be taken again.
    """
    if protocol is None or protocol.min_px_per_period is None:
        return
    got = result.px_per_period  # the shortest carrier period in px
    if got < protocol.min_px_per_period:
        raise InputError(
            f"the photo has {got:.3g} px per grid carrier period but the protocol of {spec_label} requires at least "
            f"{protocol.min_px_per_period:g} (min_px_per_period); photograph the grid closer, with a longer focal "
            "length or a coarser grid")


def _protocol_checks(protocol: Protocol, result: Result) -> list[Check]:
    checks: list[Check] = []
    if protocol.method is not None:
        checks.append(Check(f"protocol: method = {protocol.method}", result.method, protocol.method, "", "==",
                            result.method == protocol.method))
    for key, unit in (("pitch_mm", "mm"), ("distance_m", "m")):
        want = getattr(protocol, key)
        if want is not None:
            got = float(result.pitch_mm if key == "pitch_mm" else result.distance_m)
            ok = math.isclose(got, want, rel_tol=1e-6)
            checks.append(Check(f"protocol: {key} = {want:g} {unit}", got, want, unit, "==", ok,
                                "" if ok else f"rerun the analysis with the specification's {_OPTION[key]}"))
    if protocol.pattern is not None:
        checks.append(Check(f"protocol: pattern = {protocol.pattern}", result.pattern, protocol.pattern, "", "==",
                            result.pattern == protocol.pattern))
    want_sigma = protocol.sigma_mm
    if want_sigma is None and protocol.sigma_periods is not None:
        want_sigma = protocol.sigma_periods * float(result.carrier_period_mm)
    if want_sigma is not None:
        sigma = float(result.sigma_mm)
        ok = math.isclose(sigma, want_sigma, rel_tol=1e-6)
        checks.append(Check(f"protocol: sigma_mm = {want_sigma:.4g} mm", sigma, want_sigma, "mm", "==", ok,
                            "" if ok else "rerun the analysis with the specification's --sigma-mm"))
    if protocol.detrend_degree is not None:
        degree = result.detrend_degree
        ok = degree == protocol.detrend_degree
        checks.append(Check(f"protocol: detrend_degree = {protocol.detrend_degree}", degree, protocol.detrend_degree, "",
                            "==", ok, "" if ok else "rerun the analysis with the specification's --detrend-degree"))
    return checks


def spec_verdict(spec: Spec, stats: Mapping[str, Mapping[str, Any]], result: Result, *, spec_path: str = "",
                 spec_sha256: str = "", zones: Mapping[str, Mapping[str, Any]] | None = None,
                 trusted_percent: float | None = None, of_mask: bool = False) -> Verdict:
    """Check every criterion of ``spec`` against an analysis whose statistics are already computed.

    The engine under :func:`glassdist.acceptance.assess.assess`; from a result alone use
    the public ``glassdist.evaluate_spec(result, spec)``, which computes the statistics,
    zones and coverage first.

    Parameters
    ----------
    spec : Spec
    stats : dict
        ``{channel: statistics}`` from :func:`glassdist.acceptance.stats.result_statistics`,
        computed with ``over_limits_mD=spec_limits(spec)``.
    result : AnalysisResult
        For ``valid`` (coverage) and the protocol fields ``method``, ``sigma_mm``,
        ``detrend_degree``, ``pitch_mm``, ``distance_m``.
    spec_path, spec_sha256 : str
        Recorded in the verdict.
    zones : dict, optional
        ``{zone name: {"statistics": {channel: statistics}, "trusted_percent": float}}``
        (see :func:`glassdist.acceptance.zones.zone_statistics`); needed when a criterion
        or a zone limit names a zone.
    trusted_percent : float, optional
        Trusted share (percent) that ``min_valid_percent`` is checked against, as
        :func:`~glassdist.acceptance.assess.assess` computed it; default the share of the
        image, computed here.
    of_mask : bool
        ``trusted_percent`` is a share of the user's mask (named so in the check), not of
        the image.

    Returns
    -------
    Verdict

    The capture is checked beforehand (:func:`check_capture`, once per run, by
    :func:`glassdist.acceptance.assess.assess`).
    """
    zones = zones or {}
    checks = _protocol_checks(spec.protocol, result)
    if spec.min_valid_percent is not None:
        if trusted_percent is None:  # the statistics' pixels (zones.measured_region): the trusted ones
            trusted_percent = share_percent(result.trusted)
        cov = float(trusted_percent)
        where = "the mask" if of_mask else "the image"
        checks.append(Check(f"trusted area >= {spec.min_valid_percent:g} % of {where}", cov,
                            spec.min_valid_percent, "%", ">=", cov >= spec.min_valid_percent))
    for z in spec.zones:
        if z.min_valid_percent is not None:
            cov = float((zones.get(z.name) or {}).get("trusted_percent", float("nan")))
            ok = (not math.isnan(cov)) and cov >= z.min_valid_percent
            checks.append(Check(f"trusted area >= {z.min_valid_percent:g} % of zone '{z.name}'", cov,
                                z.min_valid_percent, "%", ">=", ok, "zone not in the photo" if math.isnan(cov) else ""))
    if trusted_percent is None:
        trusted_percent = share_percent(result.trusted)
    for c in spec.criteria:
        if c.zone is None:
            source, covers, cov = stats, "the mask" if of_mask else "the image", float(trusted_percent)
        else:
            judged = zones.get(c.zone) or {}
            source, covers = judged.get("statistics", {}), f"zone '{c.zone}'"
            cov = float(judged.get("trusted_percent", float("nan")))
        value = float(source.get(c.channel, {}).get(c.stat_key, float("nan")))
        limit = (c.max_percent if c.statistic == "area_over" else c.max_mD) or 0.0  # never None: the model requires it
        unit = "%" if c.statistic == "area_over" else "mD"
        ok = (not math.isnan(value)) and value <= limit
        checks.append(Check(c.describe(), value, limit, unit, "<=", ok,
                            "no valid pixel to measure" if math.isnan(value) else "", cov, covers))
    return Verdict(spec.name, str(spec_path), spec_sha256, tuple(checks))
