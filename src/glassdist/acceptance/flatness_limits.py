"""Flatness limits of an acceptance specification: upper limits on a reflection run's front-face measures.

A specification's ``flatness`` is a list of limits, each ``{"measure": ..., "max": ...}``
(passes when ``value <= max``), judged on the run's ``summary.json["flatness"]``
(:mod:`glassdist.flatness.measures`)::

    "flatness": [
      {"measure": "roller_wave_peak_to_valley_mm", "max": 0.3},
      {"measure": "edge_lift_mm", "max": 0.3}
    ]

* ``roller_wave_peak_to_valley_mm``, ``roller_wave_astm_c1651_mD``: the dominant roller wave's
  depth and its ASTM C1651 power (the verdict line gives its wavelength and direction);
* ``edge_lift_mm``: the largest ``|lift|`` of the pane edges in view (the verdict line names
  each edge's lift, and the edges not in view);
* ``height_peak_to_valley_um``: the detrended height's range over the trusted samples.

A specification may hold flatness limits only (``criteria`` then empty), not neither. A
measure the run does not give (a transmission run, no roller wave found, no edge in view)
fails its limit, saying why: a specification is never passed by what was not measured.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Literal

from pydantic import BaseModel, Field, model_validator

from ..validation import MODEL_CONFIG

if TYPE_CHECKING:
    from ..analyzer.result import Result

__all__ = ["FlatnessLimit", "WithFlatnessLimits", "flatness_checks"]

_TEXT = {"roller_wave_peak_to_valley_mm": ("roller wave peak-to-valley", "mm"),
         "roller_wave_astm_c1651_mD": ("roller wave ASTM C1651 power", "mD"),
         "edge_lift_mm": ("edge lift", "mm"),
         "height_peak_to_valley_um": ("height peak-to-valley", "um")}


class FlatnessLimit(BaseModel):
    """An upper limit on one flatness measure of a reflection run (module notes)."""

    model_config = MODEL_CONFIG

    measure: Literal["roller_wave_peak_to_valley_mm", "roller_wave_astm_c1651_mD", "edge_lift_mm",
                     "height_peak_to_valley_um"]
    max: float = Field(..., ge=0, le=1e6, allow_inf_nan=False, description="upper limit, in the measure's unit")
    label: str | None = Field(None, description="name printed in verdicts (default: built from the limit)")

    @property
    def unit(self) -> str:
        """The measure's unit."""
        return _TEXT[self.measure][1]

    def describe(self) -> str:
        """Text of the limit, e.g. ``edge lift <= 0.3 mm``."""
        text, unit = _TEXT[self.measure]
        return self.label or f"{text} <= {self.max:g} {unit}"

    def judge(self, flatness: dict[str, Any] | None) -> tuple[float, str]:
        """``(value, note)`` of this limit's measure on a ``summary.json["flatness"]`` section (None: not a
        reflection run); the value NaN where the run does not give it, the note saying why."""
        if flatness is None:
            return math.nan, "no flatness measures (a reflection run gives them)"
        if self.measure == "edge_lift_mm":
            lifts = flatness.get("edge_lift_mm") or {}
            seen = {e: v for e, v in lifts.items() if v is not None}
            if not seen:
                return math.nan, "no pane edge in view"
            worst = max(seen, key=lambda e: abs(seen[e]))
            note = (f"largest at the {worst} edge; " + ", ".join(f"{e} {v:.3g} mm" for e, v in seen.items())
                    + "".join(f"; {e} not in view" for e, v in lifts.items() if v is None))
            return abs(float(seen[worst])), note
        if self.measure.startswith("roller_wave"):
            wave = flatness.get("roller_wave")
            if wave is None:
                return math.nan, "no roller wave found"
            key = "peak_to_valley_mm" if self.measure == "roller_wave_peak_to_valley_mm" else "astm_c1651_mD"
            return float(wave[key]), f"wavelength {wave['wavelength_mm']:.4g} mm, direction {wave['direction_deg']:.3g} deg"
        return float(flatness.get("height_peak_to_valley_um", math.nan)), ""


class WithFlatnessLimits(BaseModel):
    """The ``flatness`` limits of a specification (:class:`~glassdist.acceptance.spec.Spec` derives from it)."""

    model_config = MODEL_CONFIG

    flatness: tuple[FlatnessLimit, ...] = ()

    @model_validator(mode="after")
    def _some_limit(self) -> WithFlatnessLimits:
        if not getattr(self, "criteria", ()) and not self.flatness:
            raise ValueError("a specification needs at least one entry in 'criteria' or 'flatness'")
        return self


def flatness_checks(limits: Sequence[FlatnessLimit], flatness: dict[str, Any] | None,
                    result: Result | None = None) -> list[tuple[str, float, float, str, str, bool, str]]:
    """The arguments of one :class:`~glassdist.acceptance.spec.Check` per limit: ``(criterion, value, limit,
    unit, "<=", passed, note)``. ``flatness``: the run's section; None with a ``result``: computed from it
    (:func:`glassdist.flatness.flatness_measures`)."""
    if limits and flatness is None and result is not None:
        from ..flatness.measures import flatness_measures

        measured = flatness_measures(result)
        flatness = None if measured is None else measured.to_dict()
    out = []
    for limit in limits:
        value, note = limit.judge(flatness)
        out.append((limit.describe(), value, limit.max, limit.unit, "<=", (not math.isnan(value)) and value <= limit.max,
                    note))
    return out
