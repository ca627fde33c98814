"""A4 statistical summaries of the power channels, in mD.

Statistics are taken over the valid analysis region only (``valid`` and finite):

* ``mean_abs``: mean of ``|phi|``;
* ``mean``: mean of the signed ``phi``;
* ``std``: standard deviation of the signed ``phi``;
* ``p95_abs``: 95th percentile of ``|phi|``;
* ``max_abs``: maximum of ``|phi|``;
* ``area_over_<T>``: percentage of the valid region where ``|phi| > T`` mD.

``phi_shear`` and ``phi_total`` are non-negative, so ``|phi|`` is ``phi`` for them.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any, Hashable, TypeVar

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:
    from ..analyzer.result import Result

__all__ = [
    "CHANNEL_FIELDS",
    "UNCERTAINTY_FIELDS",
    "STATISTIC_FIELDS",
    "STATISTICS",
    "shared_limit",
    "acceptance_statistics",
    "area_over_percent",
    "result_statistics",
    "regions_statistics",
    "pixel_blocks",
    "share_percent",
    "format_limit",
]

K = TypeVar("K", bound=Hashable)

#: channel name -> attribute of the analysis result holding its field (mD)
CHANNEL_FIELDS = {"phi_eff": "phi_eff_mD", "phi_shear": "phi_shear_mD", "phi_total": "phi_total_mD"}

#: standard-uncertainty channels a specification may also judge -> their fields (mD)
UNCERTAINTY_FIELDS = {"phi_eff_sigma": "phi_eff_sigma_mD", "phi_shear_sigma": "phi_shear_sigma_mD"}

#: every channel statistics can be taken of
STATISTIC_FIELDS = {**CHANNEL_FIELDS, **UNCERTAINTY_FIELDS}

#: statistics every channel reports (mD), in table order
STATISTICS = ("mean_abs", "mean", "std", "p95_abs", "max_abs")


def _values(field: ArrayLike, valid: ArrayLike | None) -> np.ndarray:
    field = np.asarray(field, dtype=np.float64)
    ok = np.isfinite(field)
    if valid is not None:
        ok &= np.asarray(valid, dtype=bool)
    return field[ok]


def format_limit(limit_mD: float) -> str:
    """Name suffix of an area-over statistic: ``area_over_<limit>`` (``12.5`` -> ``12.5``, ``100.0`` -> ``100``)."""
    return f"area_over_{float(limit_mD):g}"


def area_over_percent(field: ArrayLike, valid: ArrayLike | None = None, limit_mD: float = 0.0) -> float:
    """Percentage of the valid region where ``|field| > limit_mD``.

    Parameters
    ----------
    field : ndarray, shape (H, W)
        Channel in mD; NaN where invalid.
    valid : ndarray of bool, shape (H, W), optional
    limit_mD : float
        Threshold in mD.

    Returns
    -------
    float
        Percent (0-100) of the valid, finite pixels over the limit; NaN when the
        region is empty.
    """
    v = _values(field, valid)
    if v.size == 0:
        return float("nan")
    return float(100.0 * np.count_nonzero(np.abs(v) > limit_mD) / v.size)


def acceptance_statistics(field: ArrayLike, valid: ArrayLike | None = None, *,
                          over_limits_mD: Sequence[float] = ()) -> dict[str, Any]:
    """Statistics of one channel over the valid region, as the acceptance reports them (``area_over_<T>`` keys).

    Parameters
    ----------
    field : ndarray, shape (H, W)
        Channel in mD; NaN where invalid.
    valid : ndarray of bool, shape (H, W), optional
    over_limits_mD : sequence of float
        Thresholds (mD) for which ``area_over_<T>`` (percent) is reported.

    Returns
    -------
    dict
        ``mean_abs``, ``mean``, ``std``, ``p95_abs``, ``max_abs`` (mD),
        ``area_over_<T>`` (percent) and ``n_valid``; values are NaN when the
        region is empty. The first four and ``n_valid`` are those of
        :func:`glassdist.analyzer.metrics.channel_statistics`.
    """
    from ..analyzer.metrics import channel_statistics as base_statistics

    out: dict[str, Any] = base_statistics(np.asarray(field), None if valid is None else np.asarray(valid, dtype=bool),
                                          over_limits=over_limits_mD)
    out.update({format_limit(t): pct for t, pct in out.pop("over_percent", {}).items()})
    return out


def share_percent(region: ArrayLike, asked: ArrayLike | None = None) -> float:
    """Share (percent) of the region asked for that ``region`` covers.

    The one definition behind ``measured_percent`` (``region``: the valid pixels) and
    ``trusted_percent`` (``region``: the trusted pixels, quality label 0) of ``summary.json``,
    the console, the report, the web page and the batch index:
    ``100 * |region & asked| / |asked|``.

    Parameters
    ----------
    region : array_like of bool, shape (H, W)
    asked : array_like of bool, shape (H, W), optional
        The region asked for (the user mask); default the whole image.
    """
    r = np.asarray(region, dtype=bool)
    if asked is None:
        return float(100.0 * np.count_nonzero(r) / max(r.size, 1))
    a = np.asarray(asked, dtype=bool)
    return float(100.0 * np.count_nonzero(r & a) / max(int(np.count_nonzero(a)), 1))


def result_statistics(result: Result, *, over_limits_mD: Mapping[str, Sequence[float]] | None = None
                      ) -> dict[str, dict[str, Any]]:
    """Statistics of every channel of an analysis result.

    Parameters
    ----------
    result : Result
        An :class:`~glassdist.analyzer.result.AnalysisResult` or a
        :class:`~glassdist.storage.StoredResult`; its ``valid`` region.
    over_limits_mD : dict, optional
        ``{channel: [T, ...]}`` thresholds (mD) for the area-over statistics.

    Returns
    -------
    dict
        ``{channel: acceptance_statistics(...)}`` for each channel the result holds.
    """
    over_limits_mD = over_limits_mD or {}
    return {name: acceptance_statistics(result.pixel_field(attr), result.valid,
                                        over_limits_mD=over_limits_mD.get(name, ()))
            for name, attr in CHANNEL_FIELDS.items() if _holds(result, attr)}


def _holds(result: Result, name: str) -> bool:
    return any(f.name == name for f in result.field_specs())


def pixel_blocks(result: Result, attrs: Sequence[str], max_pixels: int = 1 << 21
                 ) -> Iterator[tuple[slice, dict[str, np.ndarray]]]:
    """``(rows, {attr: field[rows]})``: fields ``attrs`` of ``result`` on the pixel grid, by blocks of image rows.

    The result brings them there block by block (:meth:`~glassdist.analyzer.result.Result.pixel_rows`):
    no full-size copy of a field is needed.
    """
    yield from result.pixel_rows(list(attrs), max_pixels)


def _grid_brackets(result: Result, regions: Mapping[K, np.ndarray], names: Mapping[str, str]
                   ) -> dict[tuple[K, str], tuple[float, float]]:
    """``{(key, channel): (lo, hi)}``: where each region's 95th percentile lies, from the analysis-grid samples in it.

    The pixel-grid fields interpolate the analysis grid, so its samples' quantiles bracket
    the pixels' (checked; a miss costs a second look, not accuracy).
    """
    from ..analyzer.metrics import percentile_bracket

    yy, xx = result.analysis_grid.coords()
    H, W = result.valid.shape
    iy = np.clip(np.rint(yy).astype(np.intp), 0, H - 1)
    ix = np.clip(np.rint(xx).astype(np.intp), 0, W - 1)
    gv = np.asarray(result.grid_valid, bool)
    out = {}
    for key, region in regions.items():
        at = gv & np.asarray(region, bool)[iy, ix]
        for ch, attr in names.items():
            g = np.asarray(result.grid_field(attr))[at]
            out[(key, ch)] = percentile_bracket(np.abs(g), 95.0)
    return out


def regions_statistics(result: Result, regions: Mapping[K, np.ndarray], *,
                       channels: Sequence[str] = tuple(CHANNEL_FIELDS),
                       over_limits_mD: Mapping[str, Sequence[float]] | None = None,
                       max_pixels: int = 1 << 21) -> dict[K, dict[str, dict[str, Any]]]:
    """Statistics of ``channels`` of ``result`` over each of ``regions``, in one pass over the pixel grid.

    Parameters
    ----------
    result : Result
    regions : dict of key -> ndarray of bool (H, W)
    channels : sequence of str
        Names of :data:`STATISTIC_FIELDS` (those the result holds are reported).
    over_limits_mD : dict, optional
        ``{channel: [T, ...]}`` thresholds for the ``area_over_<T>`` statistics.
    max_pixels : int
        Pixels per block of rows the fields are brought to the pixel grid in.

    Returns
    -------
    dict
        ``{key: {channel: statistics}}``, each as :func:`acceptance_statistics`: the same
        values (the mean and standard deviation summed in float64 block by block, the
        percentile exact), without a full-size copy of any field.
    """
    from ..analyzer.metrics import percentile, streamed_statistics

    over_limits_mD = over_limits_mD or {}
    names = {ch: STATISTIC_FIELDS[ch] for ch in channels if _holds(result, STATISTIC_FIELDS[ch])}
    brackets = _grid_brackets(result, regions, names)
    to_channel = {attr: ch for ch, attr in names.items()}
    blocks = ((rows, {to_channel[a]: b for a, b in fields.items()})
              for rows, fields in pixel_blocks(result, list(names.values()), max_pixels))
    out: dict[K, dict[str, dict[str, Any]]] = streamed_statistics(blocks, dict(regions),
                                                                   over_limits=dict(over_limits_mD), brackets=brackets)
    for key, per in out.items():
        for ch, st in per.items():
            if st["p95_abs"] is None:  # the bracket missed: the whole field, once
                f = result.pixel_field(names[ch])
                st["p95_abs"] = percentile(np.abs(f[np.asarray(regions[key], bool) & np.isfinite(f)]), 95.0)
            st.update({format_limit(t): pct for t, pct in st.pop("over_percent", {}).items()})
    return out


def shared_limit(*fields: ArrayLike, valid: ArrayLike | None = None, percentile: float = 99.0) -> float:
    """Colour limit ``V`` (mD) shared by several channels.

    Parameters
    ----------
    *fields : ndarray, shape (H, W)
        Channel fields in mD (NaN where invalid).
    valid : ndarray of bool, shape (H, W), optional
        Region the limit is computed on.
    percentile : float
        Percentile of ``|field|`` used (robust to a few outlier pixels).

    Returns
    -------
    float
        The largest of the fields' ``percentile`` of ``|value|``, in mD; 1.0 when
        no field has a finite valid value (so that a blank plot still draws).
    """
    best = 0.0
    for f in fields:
        ok = np.isfinite(np.asarray(f, dtype=np.float64))
        if valid is not None:
            ok &= np.asarray(valid, dtype=bool)
        if ok.any():
            best = max(best, float(np.percentile(np.abs(np.asarray(f)[ok]), percentile)))
    return best if best > 0 else 1.0
