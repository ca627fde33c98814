"""Statistics of a channel over a region: one pass over a field, or streamed over blocks of image rows (A4's numbers).

:func:`channel_statistics` summarises a field (mean |x|, mean, std, p95 |x|, max |x|, the share
over given limits); :func:`streamed_statistics` gives the same over several regions from
blocks of rows, its percentile exact from a bracket (:func:`percentile_bracket`);
:func:`percentile` is :func:`numpy.percentile` (linear method), bit for bit, partitioning a
bracket only.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["channel_statistics", "percentile", "percentile_bracket", "streamed_statistics"]


def channel_statistics(field: np.ndarray, valid: np.ndarray | None = None, *, over_limits=()) -> dict:
    """Summary statistics of a channel over the valid region, from one extraction of its values.

    Parameters
    ----------
    field : ndarray
        The channel (any units); NaN where invalid.
    valid : ndarray of bool, optional
        Region the statistics are taken over (with the finite values).
    over_limits : sequence of float
        Thresholds ``T`` for the share of the region where ``|field| > T``.

    Returns
    -------
    dict
        ``mean_abs`` (mean |phi|), ``mean`` and ``std`` (of signed phi), ``p95_abs``,
        ``max_abs`` (same units as ``field``), ``n_valid`` and, with ``over_limits``,
        ``over_percent``: ``{T: percent}``. NaN values when nothing is valid.
    """
    v = np.asarray(field)
    if v.dtype.kind != "f":
        v = v.astype(float)
    m = np.isfinite(v) if valid is None else (np.asarray(valid, bool) & np.isfinite(v))
    x = v[m]
    limits = sorted(set(float(t) for t in over_limits))
    if x.size == 0:
        nan = float("nan")
        out: dict[str, Any] = {"mean_abs": nan, "mean": nan, "std": nan, "p95_abs": nan, "max_abs": nan, "n_valid": 0}
        return {**out, "over_percent": {t: nan for t in limits}} if limits else out
    # In the field's own precision (numpy's pairwise sums keep float32 means to ~1e-6):
    # float64 copies of a 24 Mpx field cost more than the statistics themselves.
    a = np.abs(x)
    out = {"mean_abs": float(a.mean()), "mean": float(x.mean()), "std": float(x.std()),
           "max_abs": float(a.max()), "n_valid": int(x.size)}
    if limits:
        out["over_percent"] = {t: float(100.0 * np.count_nonzero(a > t) / a.size) for t in limits}
    out["p95_abs"] = percentile(a, 95.0)
    return out


def percentile_bracket(sample: np.ndarray, q: float = 95.0, *, rank_margin: float = 0.02) -> tuple[float, float]:
    """Values ``(lo, hi)`` that should hold the ``q``-th percentile of a population ``sample`` comes from.

    The sample's quantiles at ranks ``q/100 -/+ (rank_margin + 6 standard errors)``;
    ``(-inf, inf)`` for a sample of fewer than 400 values. :func:`streamed_statistics`
    checks the bracket against the population's counts, so a wrong one costs time, never
    accuracy.
    """
    a = np.asarray(sample, dtype=np.float64).ravel()
    a = a[np.isfinite(a)]
    if a.size < 400:
        return -np.inf, np.inf
    p = q / 100.0
    m = rank_margin + 6.0 * np.sqrt(p * (1.0 - p) / a.size)
    lo = float(np.quantile(a, p - m)) if p - m > 0 else -np.inf
    hi = float(np.quantile(a, p + m)) if p + m < 1 else np.inf
    return lo, hi


class _Running:
    """Running statistics of one channel over one region, block by block (see :func:`streamed_statistics`)."""

    def __init__(self, limits, bracket):
        self.n, self.mean, self.m2, self.sum_abs, self.max_abs = 0, 0.0, 0.0, 0.0, -np.inf
        self.limits, self.over = limits, np.zeros(len(limits), np.int64)
        self.lo, self.hi = bracket
        self.below, self.inside = 0, []

    def add(self, x: np.ndarray) -> None:
        if x.size == 0:
            return
        a = np.abs(x)
        x64 = x.astype(np.float64)
        n_b, mean_b = x64.size, float(x64.mean())
        d = x64 - mean_b
        m2_b = float(np.dot(d, d))
        delta, n = mean_b - self.mean, self.n + n_b  # Chan et al.'s pairwise update
        self.mean += delta * n_b / n
        self.m2 += m2_b + delta * delta * self.n * n_b / n
        self.n = n
        self.sum_abs += float(a.sum(dtype=np.float64))
        self.max_abs = max(self.max_abs, float(a.max()))
        for i, t in enumerate(self.limits):
            self.over[i] += np.count_nonzero(a > t)
        if np.isfinite(self.lo) or np.isfinite(self.hi):
            self.below += int(np.count_nonzero(a < self.lo))
            self.inside.append(a[(a >= self.lo) & (a <= self.hi)])
        else:
            self.inside.append(a)

    def statistics(self, q: float):
        if self.n == 0:
            nan = float("nan")
            out: dict[str, Any] = {"mean_abs": nan, "mean": nan, "std": nan, "p95_abs": nan, "max_abs": nan,
                                   "n_valid": 0}
            return {**out, "over_percent": {t: nan for t in self.limits}} if self.limits else out
        out = {"mean_abs": self.sum_abs / self.n, "mean": self.mean, "std": float(np.sqrt(self.m2 / self.n)),
               "max_abs": self.max_abs, "n_valid": int(self.n)}
        if self.limits:
            out["over_percent"] = {t: float(100.0 * c / self.n) for t, c in zip(self.limits, self.over)}
        inside = np.concatenate(self.inside) if self.inside else np.empty(0, np.float32)
        out["p95_abs"] = _bracketed_percentile(inside, self.below, self.n, q)  # None: the bracket missed
        return out


def streamed_statistics(blocks, regions: dict, *, over_limits: dict | None = None, brackets: dict | None = None,
                        q: float = 95.0) -> dict:
    """:func:`channel_statistics` of several channels over several regions, from blocks of image rows.

    One pass over the blocks, each channel's values taken once per block and region:
    the mean and standard deviation are combined exactly from per-block moments (Chan,
    Golub & LeVeque 1979) in float64, the counts summed, and the ``q``-th percentile is
    numpy's (linear method) exactly, from the values inside a bracket (``brackets``, see
    :func:`percentile_bracket`) and the count of those below it; without a bracket every
    value is kept.

    Parameters
    ----------
    blocks : iterable of (slice, dict of str -> ndarray)
        Consecutive blocks of image rows: ``(rows, {channel: field[rows]})``, NaN where invalid.
    regions : dict of key -> ndarray of bool (H, W)
    over_limits : dict, optional
        ``{channel: thresholds}`` for ``over_percent``.
    brackets : dict, optional
        ``{(key, channel): (lo, hi)}``.
    q : float
        The percentile reported as ``p95_abs``.

    Returns
    -------
    dict
        ``{key: {channel: statistics}}`` as :func:`channel_statistics`; ``p95_abs`` is None
        where its bracket missed (the caller takes it from the whole field).
    """
    over_limits, brackets = over_limits or {}, brackets or {}
    run: dict[tuple[Any, Any], _Running] = {}
    for rows, fields in blocks:
        for key, region in regions.items():
            r = np.asarray(region[rows], bool)
            for ch, block in fields.items():
                acc = run.get((key, ch))
                if acc is None:
                    limits = sorted(set(float(t) for t in over_limits.get(ch, ())))
                    acc = run[(key, ch)] = _Running(limits, brackets.get((key, ch), (-np.inf, np.inf)))
                acc.add(block[r & np.isfinite(block)])
    out: dict[Any, dict[Any, Any]] = {key: {} for key in regions}
    for (key, ch), acc in run.items():
        out[key][ch] = acc.statistics(q)
    return out


def percentile(values: np.ndarray, q: float) -> float:
    """``numpy.percentile(values, q)`` (linear method) of a 1-D array, partitioning a bracket only.

    The two order statistics around rank ``q / 100 (n - 1)`` are located from a strided
    sample of ~65 000 values: a bracket of ranks 6 standard errors wide either side of
    the sample quantile holds them unless the sample misleads, which a count of the
    values below the bracket detects (then the whole array is partitioned). On a
    24 Mpx channel this costs two comparisons and a small partition instead of an
    introselect over every value. The result is bit-identical to :func:`numpy.percentile`.

    Parameters
    ----------
    values : ndarray
        Finite values, any shape (flattened); not modified.
    q : float
        Percentile, 0-100.

    Returns
    -------
    float
    """
    a = np.asarray(values).ravel()
    n = a.size
    if n < 1 << 18:
        return float(np.percentile(a, q))
    s = np.sort(a[:: n >> 16])
    j = (n - 1) * np.true_divide(q, 100) / (n - 1) * (s.size - 1)  # the sample's rank of the percentile
    margin = 6.0 * np.sqrt(s.size * 0.25) + 2.0
    lo = s[max(int(j - margin), 0)]
    hi = s[min(int(np.ceil(j + margin)), s.size - 1)]
    found = _bracketed_percentile(a[(a >= lo) & (a <= hi)], int(np.count_nonzero(a < lo)), n, q)
    if found is not None:
        return found
    whole = _bracketed_percentile(a, 0, n, q)  # the sample misled: every value
    assert whole is not None  # every value is inside
    return whole


def _bracketed_percentile(inside: np.ndarray, below: int, n: int, q: float) -> float | None:
    """numpy's ``q``-th percentile (linear method) of ``n`` values, from those ``inside`` a bracket and the
    count ``below`` it; None when the two order statistics it needs are not inside."""
    virtual = (n - 1) * np.true_divide(q, 100)
    k = int(np.floor(virtual))
    gamma = float(virtual - k)
    k1 = min(k + 1, n - 1)
    if not (below <= k and below + inside.size > k1):
        return None
    low, high = np.partition(inside, (k - below, k1 - below))[[k - below, k1 - below]]
    # numpy's linear interpolation (_lerp), operation for operation
    diff = high - low
    return float(high - diff * (1 - gamma) if gamma >= 0.5 else low + diff * gamma)
