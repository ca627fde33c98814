"""The summary sections a result's physics adds beyond its own record: flatness (reflection) and intrinsic reading.

Computed once on the analysis side, from the result and the run's camera distance, and handed to
the run record (:func:`glassdist.storage.record.build_record`), which only serialises them:

* ``flatness``: the front face's measures in mm and µm of a reflection result
  (:func:`glassdist.flatness.flatness_measures`);
* ``intrinsic``: the pane's intrinsic reading of a transmission result given the camera-to-pane
  distance (:func:`glassdist.viewpoint.intrinsic.reading_of_result`).
"""

from __future__ import annotations

from typing import Any

__all__ = ["result_sections"]


def result_sections(result, *, camera_distance_m: float | None = None, pose=None) -> dict[str, Any]:
    """``{"flatness": ..., "intrinsic": ...}``, each present only where it applies (module notes).

    Parameters
    ----------
    result : AnalysisResult
    camera_distance_m : float, optional
        Camera to pane, m: with a transmission result, its intrinsic reading.
    pose : CapturePose, optional
        The capture's angle to the pane and its sources (:mod:`glassdist.viewpoint.pose`);
        None: normal incidence.

    Returns
    -------
    dict
        JSON-serialisable sections of ``summary.json``.
    """
    from .analyzer.region import BEYOND_RANGE, LOW_MODULATION
    from .flatness.measures import flatness_measures

    out: dict[str, Any] = {}
    flat = flatness_measures(result, beyond_edge_labels=(LOW_MODULATION, BEYOND_RANGE))  # reflection only
    if flat is not None:
        out["flatness"] = flat.to_dict()
    if camera_distance_m is not None and result.optics is None:
        from .viewpoint.intrinsic import intrinsic_section, reading_of_result

        reading = reading_of_result(result, camera_distance_m, geometry=None if pose is None else pose.geometry)
        out["intrinsic"] = intrinsic_section(reading, result.trusted, None if pose is None else pose.sources())
    return out
