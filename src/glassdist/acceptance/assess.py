"""Acceptance record of one analysis: protocol, pane and zones, worst regions, verdict, pane metadata.

:func:`assess` gathers what a specification asks of an analysis into one
:class:`Acceptance` (no file read or written, nothing drawn); the storage writes its
:meth:`~Acceptance.summary` into ``summary.json`` and :meth:`~Acceptance.regions_csv`
as ``worst_regions.csv``; :mod:`glassdist.report.maps` draws its zones and numbered
worst regions on the heatmaps.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from .flatness_limits import flatness_checks
from .geometry import MD_STATISTICS
from .regions import REGION_CHANNELS, all_worst_regions, regions_csv
from .spec import _STAT_TEXT, _SYMBOL, Check, as_spec, check_capture, spec_channels, spec_limits, spec_verdict
from .stats import CHANNEL_FIELDS, regions_statistics, share_percent, shared_limit
from .zones import PaneFrame, check_pane, measured_region, pane_frame, zone_masks, zone_statistics

if TYPE_CHECKING:
    from ..analyzer.result import Result
    from .spec import LoadedSpec, ResolvedProtocol, Spec, Verdict

__all__ = ["Acceptance", "assess", "colour_limits", "METADATA_KEYS"]

#: pane facts a report states (given on the command line, in a batch manifest or to the API)
METADATA_KEYS = ("pane_id", "site", "operator")


@dataclass(frozen=True)
class Acceptance:
    """What a specification asks of one analysis (see :func:`assess`).

    Attributes
    ----------
    stats : dict
        ``{channel: statistics}`` over the analysed region (the result's trusted pixels,
        :func:`~glassdist.acceptance.zones.measured_region`; with the spec's area-over values).
    frame : PaneFrame
        The pane and its millimetre frame.
    zones : dict
        ``{name: {"definition", "area_mm2", "analysed_area_mm2", "trusted_percent", "statistics"}}``.
    masks : dict
        ``{name: bool (H, W)}`` of each zone.
    regions : dict
        ``{channel: {"threshold_mD", "threshold_source", "regions"}}``.
    verdict : Verdict or None
    measured_percent : float
        Share (percent) of the region asked for (the mask, else the image) that carries a
        measurement (the result's ``valid`` pixels).
    trusted_percent : float
        Share (percent) of the region asked for that is trusted (quality label 0): the pixels
        every statistic and verdict covers (:func:`~glassdist.acceptance.zones.measured_region`).
    protocol : dict or None
        :meth:`ResolvedProtocol.to_dict` with the values the analysis used.
    metadata : dict
        Pane ID, site, operator (given) and camera (EXIF).
    colour_limits : dict
        ``{channel: mD}`` of the heatmaps.
    warnings : tuple of str
    """

    stats: dict[str, dict[str, Any]]
    frame: PaneFrame
    zones: dict[str, dict[str, Any]]
    masks: dict[str, np.ndarray]
    regions: dict[str, dict[str, Any]]
    verdict: Verdict | None
    measured_percent: float
    trusted_percent: float
    protocol: dict[str, Any] | None
    metadata: dict[str, Any]
    colour_limits: dict[str, float]
    warnings: tuple[str, ...] = field(default=())

    def summary(self) -> dict[str, Any]:
        """Additions to ``summary.json``: ``protocol``, ``pane``, ``zones``, ``worst_regions``, ``metadata``,
        ``measured_percent``, ``trusted_percent``, ``colour_limits_mD``."""
        return {
            "protocol": self.protocol,
            "pane": self.frame.to_dict(),
            "zones": self.zones,
            "worst_regions": {ch: {"threshold_mD": e["threshold_mD"], "threshold_source": e["threshold_source"],
                                   "units": self.frame.units, "regions": [r.to_dict() for r in e["regions"]]}
                              for ch, e in self.regions.items()},
            "metadata": self.metadata,
            "measured_percent": self.measured_percent,
            "trusted_percent": self.trusted_percent,
            "colour_limits_mD": self.colour_limits,
        }

    def regions_csv(self) -> str:
        """``worst_regions.csv`` text."""
        return regions_csv(self.regions)


def colour_limits(result: Result, spec: Spec | None = None, channels: Sequence[str] = ("phi_eff", "phi_shear"), *,
                  limits: Mapping[str, Sequence[float]] | None = None) -> dict[str, float]:
    """Colour limit (mD) of each heatmap: the spec's choice (``figures.colour_limit``), else a shared p99.

    The shared p99 is taken where the heatmaps are drawn from: the trusted samples of the
    analysis grid.

    ``limits``: :func:`~glassdist.acceptance.spec.spec_limits` of ``spec`` when already
    computed (:attr:`LoadedSpec.limits <glassdist.acceptance.spec.LoadedSpec>`).

    Returns
    -------
    dict
        ``{channel: vmax_mD}``.
    """
    maps = [result.grid_field(CHANNEL_FIELDS[c]) for c in channels]
    valid = np.asarray(result.grid_valid, bool) & np.asarray(result.grid_trusted, bool)
    shared = shared_limit(*maps, valid=valid)
    choice = spec.figures.colour_limit if spec is not None else "auto"
    if choice == "auto":
        return {c: shared for c in channels}
    if choice != "spec" or spec is None:
        return {c: float(choice) for c in channels}
    limits = spec_limits(spec) if limits is None else limits
    return {c: float(min(limits[c])) if limits.get(c) else shared for c in channels}


def assess(result: Result, spec: LoadedSpec | Spec | Mapping[str, Any] | str | Path | None = None, *,
           protocol: ResolvedProtocol | None = None, mask: np.ndarray | None = None,
           metadata: Mapping[str, Any] | None = None, camera: dict[str, Any] | None | Literal[False] = False,
           camera_distance_m: float | None = None, flatness: dict[str, Any] | None = None) -> Acceptance:
    """Capture check, statistics, pane frame, zones, worst regions and verdict of one analysis.

    Parameters
    ----------
    result : AnalysisResult
    spec : LoadedSpec, Spec, dict or path, optional
        The specification (:func:`~glassdist.acceptance.spec.as_spec`; its path and
        SHA-256 are recorded in the verdict). Without one: whole-region statistics, the
        pane found in the image, worst regions over the default threshold, no verdict.
    protocol : ResolvedProtocol, optional
        The settings resolved from the options and the spec (recorded).
    mask : ndarray of bool, shape (H, W), optional
        The user's region to analyse: ``measured_percent`` and ``trusted_percent`` are shares of it.
    metadata : dict, optional
        ``pane_id``, ``site``, ``operator`` (None values left out).
    camera : dict or None, optional
        The camera facts of the photograph's EXIF (:func:`glassdist.io.camera_metadata`;
        None: the photo has none), recorded with the metadata; left out when no photo
        is known.
    camera_distance_m : float, optional
        The camera-to-pane distance (``--camera-distance-m``): a specification's
        ``reference_geometry`` converts the capture with it.
    flatness : dict, optional
        The run's ``summary.json["flatness"]`` (:func:`glassdist.sections.result_sections`), judged by
        the spec's flatness limits (:mod:`~glassdist.acceptance.flatness_limits`); default computed
        from the result where the spec has any.

    Returns
    -------
    Acceptance

    Raises
    ------
    InputError
        The capture violates the protocol's capture limits, or the specification's pane or a
        zone lies outside the photo or disagrees with its measured scale
        (:func:`~glassdist.acceptance.zones.check_pane`).
    """
    loaded = as_spec(spec) if spec is not None else None
    judged = loaded.spec if loaded is not None else None
    limits = loaded.limits if loaded is not None else {}
    if loaded is not None and judged is not None:  # a capture outside the protocol is not judged (exit 2)
        check_capture(judged.protocol, result, spec_label=loaded.label)
        check_pane(judged.pane, judged.zones, result, spec_label=loaded.label)
    # the power channels always; the uncertainty channels where a criterion judges them
    channels = tuple(dict.fromkeys((*CHANNEL_FIELDS, *(spec_channels(judged) if judged is not None else ()))))
    measured = measured_region(result)
    frame = pane_frame(result, judged.pane if judged is not None else None)
    zones_def = judged.zones if judged is not None else ()
    masks = zone_masks(frame, zones_def)
    # the whole region and every zone in one pass over the pixel grid
    regions: dict[str | None, np.ndarray] = {None: measured, **{z.name: measured & masks[z.name] for z in zones_def}}
    per_region = regions_statistics(result, regions, over_limits_mD=limits, channels=channels)
    stats = per_region.pop(None)
    zones = zone_statistics(result, frame, zones_def, over_limits_mD=limits, masks=masks, channels=channels,
                            statistics={k: v for k, v in per_region.items() if k is not None})
    trusted = share_percent(measured, mask)
    measured_share = share_percent(result.valid, mask)
    verdict = None
    if loaded is not None and judged is not None:
        # a specification at a stated geometry judges the capture converted there, and says by what factor
        geo, k = _geometry_check(judged, stats, result, camera_distance_m)
        judged_stats, judged_zones = (stats, zones) if geo is None else _converted(stats, zones, k)
        verdict = spec_verdict(judged, judged_stats, result, spec_path=loaded.path, spec_sha256=loaded.sha256,
                               zones=judged_zones, trusted_percent=trusted, of_mask=mask is not None)
        if geo is not None:
            verdict = replace(verdict, checks=(geo, *verdict.checks))
        if judged.flatness:  # the flatness limits (acceptance.flatness_limits), after the channels' criteria
            extra = tuple(Check(*args) for args in flatness_checks(judged.flatness, flatness, result))
            verdict = replace(verdict, checks=verdict.checks + extra)
    worst = all_worst_regions(result, frame, judged, channels=REGION_CHANNELS, statistics=stats, limits=limits)
    meta = {k: v for k, v in (metadata or {}).items() if v is not None}
    if camera is not False:
        meta["camera"] = camera
    proto = None
    if protocol is not None:
        proto = protocol.to_dict()
    if proto is not None or judged is not None:
        proto = proto or {"pinned": judged.protocol.model_dump(exclude_none=True) if judged is not None else {}}
        proto["used"] = {"method": result.method, "pitch_mm": result.pitch_mm, "distance_m": result.distance_m,
                         "pattern": result.pattern,
                         "sigma_mm": result.sigma_mm, "detrend_degree": result.detrend_degree,
                         "px_per_period": result.px_per_period}
    warnings = (frame.warning,) if frame.warning and zones_def else ()
    return Acceptance(stats, frame, zones, masks, worst, verdict, measured_share, trusted, proto, meta,
                      colour_limits(result, judged, limits=limits), warnings)


def _geometry_check(spec: Spec, stats: dict[str, Any], result: Result,
                    camera_distance_m: float | None) -> tuple[Check | None, float]:
    """``(Check, k)``: the check stating the conversion to ``spec.reference_geometry`` and its factor;
    ``(None, 1)`` for a specification without one.

    ``k = F_ref / F_cap`` (:func:`glassdist.viewpoint.reference_factor`) for a transmission capture
    of known camera-to-pane distance; otherwise the check fails (a specification at a stated
    geometry never passes unconverted; its criteria are then judged as captured, ``k = 1``).
    """
    if spec.reference_geometry is None:
        return None, 1.0
    ref = spec.reference_geometry
    label = f"reference geometry: {ref.describe()}"
    if camera_distance_m is None or result.optics is not None:
        why = ("the capture's camera-to-pane distance is unknown: analyse with --camera-distance-m"
               if camera_distance_m is None else "a reflection capture cannot be converted")
        return Check(label, "not converted", "converted", "", "==", False, why), 1.0
    from ..viewpoint.intrinsic import CaptureGeometry, reference_factor

    capture = CaptureGeometry(float(camera_distance_m), float(result.distance_m))
    k = reference_factor(capture, ref)
    c0 = spec.criteria[0]
    y = float(stats.get(c0.channel, {}).get(c0.stat_key, float("nan")))
    stat = _STAT_TEXT[c0.statistic].format(c=_SYMBOL[c0.channel])
    note = (f"at the specification's geometry this pane reads {y * k:.4g} mD; at the capture geometry {y:.4g} mD "
            f"({stat}, camera {capture.camera_distance_m:g} m, backdrop {capture.distance_m:g} m): the difference "
            f"is geometry (factor {k:.4g}), not glass")
    return Check(label, round(k, 6), "converted", "", "factor", True, note), k


def _converted(stats: dict[str, Any], zones: dict[str, Any] | None, k: float
               ) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(stats, zones)`` with every statistic in mD (:data:`MD_STATISTICS`) multiplied by ``k`` (copies)."""
    def scale(per_channel: dict[str, Any]) -> dict[str, Any]:
        return {ch: {key: v * k if key in MD_STATISTICS else v for key, v in st.items()} if isinstance(st, dict) else st
                for ch, st in per_channel.items()}

    zones_k = {name: {**z, "statistics": scale(z.get("statistics", {}))} for name, z in (zones or {}).items()}
    return scale(stats), zones_k
