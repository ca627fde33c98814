"""The geometry a specification's limits hold at, and the conversion of a capture to it.

A specification's ``reference_geometry`` (:class:`ReferenceGeometry`) states where its limits
are to be read from (an observer's distance, the background's, the angle) or that they judge
the pane's intrinsic channels. The verdict (:func:`glassdist.acceptance.assess.assess`)
multiplies the capture's statistics in mD by the factor ``k`` of
:func:`glassdist.viewpoint.reference_factor` and states it as a check of its own: "at the
specification's geometry this pane reads X mD; at the capture geometry Y mD: the difference is
geometry (factor k), not glass."
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from pydantic import BaseModel, Field, model_validator

from ..validation import MODEL_CONFIG

__all__ = ["MD_STATISTICS", "ReferenceGeometry", "check_convertible"]

#: The statistics in mD that the geometry's factor converts (counts and area shares are left).
MD_STATISTICS = frozenset({"mean_abs", "mean", "std", "p95_abs", "max_abs"})


class ReferenceGeometry(BaseModel):
    """The viewing geometry a specification's limits hold at (``glassdist view``'s conventions).

    ``observer_distance_m`` (observer to the pane centre along the line of sight),
    ``background_distance_m`` (pane to what is seen through it), ``viewing_angle_deg`` (line
    of sight to the pane normal, below 70) and ``viewing_azimuth_deg``; or ``intrinsic: true``
    (the pane's own channels, :mod:`glassdist.viewpoint.intrinsic`), without distances.
    """

    model_config = MODEL_CONFIG

    intrinsic: bool = False
    observer_distance_m: float | None = Field(None, gt=0, le=10_000)
    background_distance_m: float | None = Field(None, gt=0, le=10_000)
    viewing_angle_deg: float = Field(0.0, ge=0, lt=70)
    viewing_azimuth_deg: float = Field(0.0, ge=-360, le=360)

    @model_validator(mode="after")
    def _one_kind(self) -> ReferenceGeometry:
        given = self.observer_distance_m is not None and self.background_distance_m is not None
        if self.intrinsic == given or (not given and (self.observer_distance_m or self.background_distance_m)):
            raise ValueError("'reference_geometry' takes either 'intrinsic': true or both 'observer_distance_m' and "
                             "'background_distance_m' (m)")
        return self

    def describe(self) -> str:
        """``"intrinsic"`` or ``"observer 10 m, background 50 m, 30 deg"``."""
        if self.intrinsic:
            return "intrinsic (the pane's own channels)"
        return (f"observer {self.observer_distance_m:g} m, background {self.background_distance_m:g} m, "
                f"{self.viewing_angle_deg:g} deg")


def check_convertible(reference: ReferenceGeometry | None, criteria: Sequence[Any]) -> None:
    """With a ``reference`` geometry, raise ValueError unless every criterion is a statistic in mD of a power channel
    (what one factor converts)."""
    if reference is None:
        return
    carried = [c.describe() for c in criteria if c.statistic == "area_over" or c.channel.endswith("_sigma")]
    if carried:
        raise ValueError(f"with 'reference_geometry' every criterion must be a statistic of phi_eff, phi_shear or "
                         f"phi_total in mD (converted by the geometry's factor); not: {'; '.join(carried)}")

