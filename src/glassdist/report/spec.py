"""Acceptance specifications: JSON criteria on the channel statistics, and verdicts.

A specification is a JSON object::

    {
      "name": "Line 2 acceptance, 6 mm float",
      "criteria": [
        {"channel": "phi_eff",   "statistic": "p95_abs",   "max_mD": 60},
        {"channel": "phi_shear", "statistic": "max_abs",   "max_mD": 150},
        {"channel": "phi_eff",   "statistic": "area_over", "threshold_mD": 100, "max_percent": 1.0}
      ],
      "min_valid_percent": 50,
      "protocol": {"method": "comparative", "sigma_mm": 2.0, "detrend_degree": 2}
    }

Criteria
--------
* ``statistic`` one of ``mean_abs``, ``std``, ``p95_abs``, ``max_abs`` (see
  :mod:`glassdist.report.stats`) with ``max_mD``: passes when ``value <= max_mD``;
* ``statistic`` ``area_over`` with ``threshold_mD`` and ``max_percent``: passes when
  the percentage of the valid region where ``|phi| > threshold_mD`` is
  ``<= max_percent``.
* ``min_valid_percent`` (optional): the analysed region must cover at least this
  percentage of the image, so a pane cannot pass because little of it was measured.
* ``protocol`` (optional): the analysis must have used this method, smoothing scale
  ``sigma_mm`` (mm, 1e-6 relative tolerance) and detrend degree; a mismatch fails
  the verdict, since limits only mean something on the scale they were written for.

A value that cannot be computed (empty valid region) fails its criterion. Unknown
keys are errors. Limits are in mD, percentages in percent of the valid region.

References
----------
Paper §4.1 (factory-line acceptance), §4.2 (contractual specification).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from ..errors import InputError
from .stats import format_limit, valid_percent

__all__ = ["Criterion", "Protocol", "Spec", "Check", "Verdict", "load_spec", "evaluate_spec", "spec_limits"]

_SYMBOL = {"phi_eff": "phi_eff", "phi_shear": "phi_shear", "phi_total": "phi_total"}
_STAT_TEXT = {"mean_abs": "mean |{c}|", "std": "std {c}", "p95_abs": "p95 |{c}|", "max_abs": "max |{c}|"}


class Criterion(BaseModel):
    """One acceptance criterion on one channel statistic."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    channel: Literal["phi_eff", "phi_shear", "phi_total"]
    statistic: Literal["mean_abs", "std", "p95_abs", "max_abs", "area_over"]
    max_mD: float | None = Field(None, ge=0, description="upper limit of the statistic, mD")
    threshold_mD: float | None = Field(None, ge=0, description="area_over: pixel threshold on |phi|, mD")
    max_percent: float | None = Field(None, ge=0, le=100, description="area_over: largest allowed area, percent")
    label: str | None = Field(None, description="name printed in verdicts (default: built from the criterion)")

    @model_validator(mode="after")
    def _check_limits(self):
        if self.statistic == "area_over":
            if self.threshold_mD is None or self.max_percent is None or self.max_mD is not None:
                raise ValueError("an 'area_over' criterion needs 'threshold_mD' and 'max_percent' (and no 'max_mD')")
        elif self.max_mD is None or self.threshold_mD is not None or self.max_percent is not None:
            raise ValueError(f"a '{self.statistic}' criterion needs 'max_mD' (and no 'threshold_mD'/'max_percent')")
        return self

    @property
    def stat_key(self):
        """Key of the statistic in :func:`glassdist.report.stats.channel_statistics`'s dict."""
        return format_limit(self.threshold_mD) if self.statistic == "area_over" else self.statistic

    def describe(self):
        """Text of the criterion, e.g. ``p95 |phi_eff| <= 60 mD``."""
        if self.label:
            return self.label
        c = _SYMBOL[self.channel]
        if self.statistic == "area_over":
            return f"area |{c}| > {self.threshold_mD:g} mD <= {self.max_percent:g} %"
        return f"{_STAT_TEXT[self.statistic].format(c=c)} <= {self.max_mD:g} mD"


class Protocol(BaseModel):
    """Analysis settings a specification's limits were written for (each optional)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    method: Literal["comparative", "direct"] | None = None
    sigma_mm: float | None = Field(None, gt=0, description="smoothing scale, mm")
    detrend_degree: int | None = Field(None, ge=0, le=8)


class Spec(BaseModel):
    """An acceptance specification (see the module docstring for the JSON form)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str = Field(..., min_length=1)
    description: str = ""
    criteria: tuple[Criterion, ...] = Field(..., min_length=1)
    min_valid_percent: float | None = Field(None, ge=0, le=100)
    protocol: Protocol = Protocol()


@dataclass(frozen=True)
class Check:
    """Outcome of one criterion: ``value`` compared with ``limit`` (``value <= limit`` or ``>=``)."""

    criterion: str
    value: float | str | None
    limit: float | str
    unit: str
    comparison: str
    passed: bool
    note: str = ""

    def line(self):
        """One line for the console, e.g. ``PASS  p95 |phi_eff| <= 60 mD  (value 41.2 mD)``."""
        if isinstance(self.value, float):
            value = "not computable" if math.isnan(self.value) else f"{self.value:.4g} {self.unit}".rstrip()
        else:
            value = str(self.value)
        tail = f"; {self.note}" if self.note else ""
        return f"{'PASS' if self.passed else 'FAIL'}  {self.criterion}  (value {value}{tail})"


@dataclass(frozen=True)
class Verdict:
    """Result of a specification on one analysis."""

    spec_name: str
    spec_path: str
    spec_sha256: str
    checks: tuple[Check, ...]

    @property
    def passed(self):
        """True when every check passed."""
        return all(c.passed for c in self.checks)

    @property
    def label(self):
        """``"PASS"`` or ``"FAIL"``."""
        return "PASS" if self.passed else "FAIL"

    def lines(self):
        """Console lines: one per check, then ``VERDICT: PASS|FAIL (n/m criteria passed) spec '<name>'``."""
        n_ok = sum(c.passed for c in self.checks)
        return [c.line() for c in self.checks] + [
            f"VERDICT: {self.label} ({n_ok}/{len(self.checks)} criteria passed) spec '{self.spec_name}'"
        ]

    def to_dict(self):
        """JSON-serialisable form (NaN values become ``null``)."""
        checks = []
        for c in self.checks:
            d = asdict(c)
            if isinstance(d["value"], float) and math.isnan(d["value"]):
                d["value"] = None
            checks.append(d)
        return {
            "result": self.label, "passed": self.passed, "spec_name": self.spec_name,
            "spec_path": self.spec_path, "spec_sha256": self.spec_sha256, "checks": checks,
        }


def _one_line_errors(exc: ValidationError):
    parts = []
    for err in exc.errors():
        loc = ".".join(str(x) for x in err["loc"]) or "(root)"
        if err["type"] == "extra_forbidden":
            parts.append(f"unknown key '{loc}'")
        else:
            msg = err["msg"].removeprefix("Value error, ")
            parts.append(f"'{loc}': {msg}")
    return "; ".join(parts)


def load_spec(path):
    """Read and validate a specification JSON file.

    Parameters
    ----------
    path : path
        JSON file (a top-level ``"$comment"`` key is allowed and ignored).

    Returns
    -------
    spec : Spec
    sha256 : str
        SHA-256 of the file's bytes (recorded with every verdict).

    Raises
    ------
    InputError
        Missing file, invalid JSON, unknown key, missing or out-of-range limit.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"specification file '{p}' does not exist; check the --spec path")
    raw = p.read_bytes()
    try:
        data = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        where = f" (line {exc.lineno}: {exc.msg})" if isinstance(exc, json.JSONDecodeError) else ""
        raise InputError(f"specification file '{p}' is not valid UTF-8 JSON{where}") from None
    if not isinstance(data, dict):
        raise InputError(f"specification file '{p}' must hold a JSON object with 'name' and 'criteria'")
    data.pop("$comment", None)
    try:
        spec = Spec(**data)
    except ValidationError as exc:
        raise InputError(
            f"invalid specification '{p}': {_one_line_errors(exc)}; see docs/industrial_workflow.md for the format"
        ) from None
    return spec, hashlib.sha256(raw).hexdigest()


def spec_limits(spec):
    """Thresholds per channel (mD) a spec draws masks and area statistics for.

    Returns
    -------
    dict
        ``{channel: sorted list of limits}``, the ``threshold_mD`` of area criteria
        and the ``max_mD`` of the ``max_abs`` / ``p95_abs`` criteria.
    """
    out = {}
    for c in spec.criteria:
        lim = c.threshold_mD if c.statistic == "area_over" else c.max_mD
        if c.statistic in ("area_over", "max_abs", "p95_abs"):
            out.setdefault(c.channel, set()).add(float(lim))
    return {k: sorted(v) for k, v in out.items()}


def _protocol_checks(protocol, result):
    checks = []
    if protocol.method is not None:
        got = getattr(result, "method", None)
        checks.append(Check(f"protocol: method = {protocol.method}", got, protocol.method, "", "==", got == protocol.method))
    if protocol.sigma_mm is not None:
        got = float(getattr(result, "sigma_mm", float("nan")))
        ok = math.isclose(got, protocol.sigma_mm, rel_tol=1e-6)
        checks.append(Check(f"protocol: sigma_mm = {protocol.sigma_mm:g} mm", got, protocol.sigma_mm, "mm", "==", ok,
                            "" if ok else "rerun the analysis with the specification's --sigma-mm"))
    if protocol.detrend_degree is not None:
        got = getattr(result, "detrend_degree", None)
        ok = got == protocol.detrend_degree
        checks.append(Check(f"protocol: detrend_degree = {protocol.detrend_degree}", got, protocol.detrend_degree, "",
                            "==", ok, "" if ok else "rerun the analysis with the specification's --detrend-degree"))
    return checks


def evaluate_spec(spec, stats, result, *, spec_path="", spec_sha256=""):
    """Check every criterion of ``spec`` against an analysis.

    Parameters
    ----------
    spec : Spec
    stats : dict
        ``{channel: statistics}`` from :func:`glassdist.report.stats.result_statistics`,
        computed with ``over_limits_mD=spec_limits(spec)``.
    result : AnalysisResult
        For ``valid`` (coverage) and the protocol fields ``method``, ``sigma_mm``,
        ``detrend_degree``.
    spec_path, spec_sha256 : str
        Recorded in the verdict.

    Returns
    -------
    Verdict
    """
    checks = _protocol_checks(spec.protocol, result)
    if spec.min_valid_percent is not None:
        cov = valid_percent(result.valid)
        checks.append(Check(f"analysed area >= {spec.min_valid_percent:g} % of the image", cov,
                            spec.min_valid_percent, "%", ">=", cov >= spec.min_valid_percent))
    for c in spec.criteria:
        value = float(stats.get(c.channel, {}).get(c.stat_key, float("nan")))
        limit = c.max_percent if c.statistic == "area_over" else c.max_mD
        unit = "%" if c.statistic == "area_over" else "mD"
        ok = (not math.isnan(value)) and value <= limit
        checks.append(Check(c.describe(), value, limit, unit, "<=", ok,
                            "no valid pixel to measure" if math.isnan(value) else ""))
    return Verdict(spec.name, str(spec_path), spec_sha256, tuple(checks))
