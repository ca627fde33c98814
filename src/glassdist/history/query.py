"""Reading the history: filtered runs as records, and the control chart of one statistic per lot.

A run's *value* is one statistic of one channel over one zone (``--zone``,
``--statistic CHANNEL.STATISTIC``; default the whole analysed region's
``phi_eff.p95_abs``). The trend of a lot is its runs' values in recording order with an
individuals control chart (Shewhart): the centre line is the lot's mean
:math:`\\bar x`, the control limits :math:`\\bar x \\pm 3 s` with :math:`s` the sample
standard deviation of the lot's values (``ddof = 1``), and a run beyond either limit is
out of control (marked in red). Limits are those of the runs selected (date, site... filters
apply), so that the chart answers "how has lot 42 moved since Monday?".
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, fields
from datetime import datetime, timedelta, timezone

import numpy as np

from ..errors import InputError
from .models import REGION

__all__ = ["HistoryFilter", "Trend", "COLUMNS", "query_runs", "trends", "plot_trends", "parse_date",
           "parse_statistic", "statistic_unit", "statistic_range"]

_STAT_RE = re.compile(r"^([a-z_]+)\.([A-Za-z0-9_]+)$")
#: columns of a history record, in order (``value``: the selected statistic; ``valid_percent``: the measured share,
#: ``trusted_percent``: the trusted share a specification judges; ``protocol``, ``measures``: as ``summary.json``)
COLUMNS = ("run", "record_id", "recorded_utc", "source", "job", "pane_id", "lot", "site", "operator", "camera",
           "verdict", "spec_name", "spec_sha256", "exit_code", "zone", "statistic", "value", "phi_eff_p95_abs_mD",
           "phi_shear_p95_abs_mD", "roller_wave_pv_mm", "edge_lift_mm", "valid_percent", "trusted_percent", "method",
           "pattern", "pitch_mm", "distance_m", "sigma_mm", "detrend_degree", "protocol", "measures", "image", "image_sha256",
           "reference",
           "reference_sha256", "warnings", "out_dir", "glassdist_version")

#: the statistics that cannot be negative, and their range (a control limit beyond it is drawn at its edge)
_RANGES = {"mean_abs": (0.0, math.inf), "std": (0.0, math.inf), "p95_abs": (0.0, math.inf),
           "max_abs": (0.0, math.inf), "n_valid": (0.0, math.inf), "coverage_percent": (0.0, 100.0)}


def statistic_unit(statistic: str) -> str:
    """The unit of ``CHANNEL.STATISTIC`` as recorded: mD, % (coverage, area over a threshold), samples, or mm
    (channel ``flatness``: a reflection run's roller-wave depth and largest edge lift)."""
    channel, stat = parse_statistic(statistic)
    if channel == "flatness":
        return "mm"
    if channel == "region" or stat.startswith("area_over") or stat.endswith("_percent"):
        return "%"
    return "samples" if stat == "n_valid" else "mD"


def statistic_range(statistic: str) -> tuple[float, float]:
    """The values ``CHANNEL.STATISTIC`` can take: ``(0, inf)`` for the non-negative ones, ``(0, 100)`` for a share."""
    channel, stat = parse_statistic(statistic)
    if stat.startswith("area_over") or stat.endswith("_percent"):
        return (0.0, 100.0)
    if channel in ("phi_shear", "phi_total", "flatness") or channel.endswith("_sigma"):  # non-negative: every statistic
        return (0.0, math.inf)
    return _RANGES.get(stat, (-math.inf, math.inf))


def parse_statistic(text: str) -> tuple[str, str]:
    """``'phi_eff.p95_abs'`` -> ``('phi_eff', 'p95_abs')``; InputError for anything else."""
    m = _STAT_RE.match(text or "")
    if not m:
        raise InputError(f"statistic '{text}' must be CHANNEL.STATISTIC, e.g. phi_eff.p95_abs or phi_shear.max_abs")
    return m.group(1), m.group(2)


def parse_date(text: str, *, end: bool = False) -> datetime:
    """``YYYY-MM-DD`` (the whole day; ``end``: up to its end) or ISO date-time, UTC."""
    try:
        value = datetime.fromisoformat(text.strip())
    except (ValueError, AttributeError):
        raise InputError(f"date '{text}' must be YYYY-MM-DD or YYYY-MM-DDTHH:MM (UTC)") from None
    if value.tzinfo is not None:
        value = value.astimezone(timezone.utc).replace(tzinfo=None)
    if end and len(text.strip()) <= 10:
        value += timedelta(days=1)
    return value


@dataclass(frozen=True)
class HistoryFilter:
    """What to select from the history (every field optional; ``None``: any).

    Attributes
    ----------
    pane_id, lot, site, operator, source : str
        Exact matches.
    verdict : {'PASS', 'FAIL', 'none'}
        ``none``: runs without a specification.
    since, until : datetime
        Recorded at or after ``since``, before ``until`` (UTC).
    zone : str
        Zone of the selected statistic (default the whole analysed region, ``all``).
    statistic : str
        ``CHANNEL.STATISTIC`` shown as ``value`` (default ``phi_eff.p95_abs``). When
        ``zone`` or ``statistic`` is given, runs without it are left out.
    above, below : float
        Keep runs whose value is above / below (mD, or % for coverage).
    failed_zone : str
        Keep runs with a failed check in this zone (e.g. ``edge``).
    limit : int
        At most this many runs, the newest.
    """

    pane_id: str | None = None
    lot: str | None = None
    site: str | None = None
    operator: str | None = None
    source: str | None = None
    verdict: str | None = None
    since: datetime | None = None
    until: datetime | None = None
    zone: str | None = None
    statistic: str | None = None
    above: float | None = None
    below: float | None = None
    failed_zone: str | None = None
    limit: int | None = None

    @classmethod
    def of(cls, **kw) -> HistoryFilter:
        """From keyword arguments (dates as text or datetime); InputError for an unknown one."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(kw) - known)
        if unknown:
            raise InputError(f"unknown history filter(s) {', '.join(unknown)}; use {', '.join(sorted(known))}")
        for key in ("since", "until"):
            if isinstance(kw.get(key), str):
                kw[key] = parse_date(kw[key], end=key == "until")
        if kw.get("verdict") is not None and str(kw["verdict"]).upper() not in ("PASS", "FAIL", "NONE"):
            raise InputError(f"verdict '{kw['verdict']}' must be PASS, FAIL or none")
        if kw.get("statistic") is not None:
            parse_statistic(kw["statistic"])
        return cls(**kw)

    @property
    def key(self) -> tuple[str, str, str]:
        """``(zone, channel, statistic)`` of the selected value."""
        channel, stat = parse_statistic(self.statistic or "phi_eff.p95_abs")
        return (self.zone or REGION, channel, stat)

    @property
    def requires_value(self) -> bool:
        """True when the filter asks for a statistic's value (a zone, a statistic or a bound)."""
        return any(v is not None for v in (self.zone, self.statistic, self.above, self.below))


def _run_ids(flt: HistoryFilter):
    """SELECT of the ids of the runs ``flt`` keeps."""
    from sqlalchemy import and_, exists, select

    from .models import CheckRow, Run, StatisticRow

    q = select(Run.id)
    for col in ("pane_id", "lot", "site", "operator", "source"):
        if getattr(flt, col) is not None:
            q = q.where(getattr(Run, col) == getattr(flt, col))
    if flt.verdict is not None:
        v = flt.verdict.upper()
        q = q.where(Run.verdict.is_(None) if v == "NONE" else Run.verdict == v)
    if flt.since is not None:
        q = q.where(Run.recorded_utc >= flt.since)
    if flt.until is not None:
        q = q.where(Run.recorded_utc < flt.until)
    if flt.failed_zone is not None:
        q = q.where(exists().where(and_(CheckRow.run_id == Run.id, CheckRow.zone == flt.failed_zone,
                                        CheckRow.passed.is_(False))))
    if flt.requires_value:
        zone, channel, stat = flt.key
        cond = [StatisticRow.run_id == Run.id, StatisticRow.zone == zone, StatisticRow.channel == channel,
                StatisticRow.statistic == stat]
        if flt.above is not None:
            cond.append(StatisticRow.value > flt.above)
        if flt.below is not None:
            cond.append(StatisticRow.value < flt.below)
        q = q.where(exists().where(and_(*cond)))
    if flt.limit is not None:
        q = q.order_by(Run.recorded_utc.desc(), Run.id.desc()).limit(int(flt.limit))
    return q


def query_runs(store, flt: HistoryFilter = HistoryFilter()) -> list[dict]:
    """The runs ``flt`` selects, oldest first, as records with :data:`COLUMNS`.

    Parameters
    ----------
    store : Store or None
        :func:`glassdist.history.store.open_store` (None: an empty history).
    flt : HistoryFilter

    Returns
    -------
    list of dict
        ``recorded_utc`` as ISO text (UTC), ``warnings`` as a list; ``value`` the
        selected statistic (None where the run has none).
    """
    if store is None:
        return []
    from sqlalchemy import String, select, tuple_, type_coerce

    from .models import Run, StatisticRow

    ids = _run_ids(flt).subquery()
    zone, channel, stat = flt.key
    keys = {(zone, channel, stat), (REGION, "phi_eff", "p95_abs"), (REGION, "phi_shear", "p95_abs"),
            (REGION, "flatness", "roller_wave_peak_to_valley_mm"), (REGION, "flatness", "edge_lift_max_mm")}
    # time and warnings as stored (text on SQLite): turned into ISO text and a list below, without a parse per row
    cols = [Run.id, Run.record_id, type_coerce(Run.recorded_utc, String).label("recorded_utc"), Run.source, Run.job,
            Run.pane_id, Run.lot, Run.site, Run.operator, Run.camera, Run.verdict, Run.spec_name, Run.spec_sha256,
            Run.exit_code, Run.valid_percent, Run.trusted_percent, Run.method, Run.pattern, Run.pitch_mm,
            Run.distance_m, Run.sigma_mm, Run.detrend_degree, Run.protocol, Run.measures, Run.image,
            Run.image_sha256, Run.reference, Run.reference_sha256,
            type_coerce(Run.warnings, String).label("warnings"), Run.out_dir, Run.glassdist_version]
    with store.engine.connect() as conn:
        runs = conn.execute(select(*cols).where(Run.id.in_(select(ids.c.id))).order_by(Run.recorded_utc, Run.id)).all()
        stats = conn.execute(
            select(StatisticRow.run_id, StatisticRow.zone, StatisticRow.channel, StatisticRow.statistic,
                   StatisticRow.value)
            .where(StatisticRow.run_id.in_(select(ids.c.id)),
                   tuple_(StatisticRow.zone, StatisticRow.channel, StatisticRow.statistic).in_(sorted(keys)))).all()
    values = {(r, z, c, s): v for r, z, c, s, v in stats}
    names = ["run"] + [c.key if hasattr(c, "key") else c.name for c in cols[1:]]
    label = f"{channel}.{stat}"
    out = []
    for row in runs:
        rec = dict(zip(names, row))
        rid = rec["run"]
        rec["recorded_utc"] = _iso(rec["recorded_utc"])
        rec.update(zone=zone, statistic=label, value=values.get((rid, zone, channel, stat)),
                   phi_eff_p95_abs_mD=values.get((rid, REGION, "phi_eff", "p95_abs")),
                   phi_shear_p95_abs_mD=values.get((rid, REGION, "phi_shear", "p95_abs")),
                   roller_wave_pv_mm=values.get((rid, REGION, "flatness", "roller_wave_peak_to_valley_mm")),
                   edge_lift_mm=values.get((rid, REGION, "flatness", "edge_lift_max_mm")),
                   warnings=_list(rec["warnings"]))
        out.append({c: rec[c] for c in COLUMNS})
    return out


def _iso(value) -> str:
    """A stored time as ISO text to the second: SQLite gives ``YYYY-MM-DD HH:MM:SS[.ffffff]``, servers a datetime."""
    if isinstance(value, datetime):
        return value.isoformat(timespec="seconds")
    return str(value)[:19].replace(" ", "T")


def _list(value) -> list:
    if value is None or isinstance(value, list):
        return list(value or [])
    return json.loads(value) if value not in ("[]", "") else []


@dataclass(frozen=True)
class Trend:
    """The control chart of one lot: its runs' values in recording order and their limits.

    Attributes
    ----------
    lot : str
    runs : tuple of int
        Run ids.
    times : tuple of str
        Recording times (ISO, UTC).
    values : ndarray
        The statistic of each run (in ``unit``).
    mean, sigma : float
        Centre line and sample standard deviation (``nan`` for fewer than two runs).
    lower, upper : float
        ``mean - 3 sigma``, ``mean + 3 sigma``, each clipped to the range the statistic
        can take (:func:`statistic_range`: a p95 of ``|phi|`` has no limit below 0 mD).
    out : ndarray of bool
        Runs beyond a control limit.
    pane_ids : tuple of str
        Each run's pane id (``''`` where none was given).
    statistic : str
        ``CHANNEL.STATISTIC`` of the values.
    unit : str
        Their unit (:func:`statistic_unit`).
    """

    lot: str
    runs: tuple
    times: tuple
    values: np.ndarray
    mean: float
    sigma: float
    lower: float
    upper: float
    out: np.ndarray
    pane_ids: tuple = ()
    statistic: str = "phi_eff.p95_abs"
    unit: str = "mD"

    def to_dict(self) -> dict:
        """The trend as a JSON-ready mapping (lot, statistic, unit, mean, sigma, limits, runs)."""
        return {"lot": self.lot, "statistic": self.statistic, "unit": self.unit, "mean": self.mean,
                "sigma": self.sigma, "lower": self.lower, "upper": self.upper, "runs": list(self.runs),
                "pane_ids": list(self.pane_ids),
                "out_of_control": [r for r, o in zip(self.runs, self.out) if o]}


def trends(records: list[dict]) -> list[Trend]:
    """One :class:`Trend` per lot of the records (runs without a value or a lot are left out), by lot name.

    The limits :math:`\\bar x \\pm 3 s` are clipped to the statistic's range
    (:func:`statistic_range`); a run is out of control beyond them.
    """
    by_lot: dict[str, list[dict]] = {}
    for r in records:
        if r.get("value") is not None and r.get("lot"):
            by_lot.setdefault(str(r["lot"]), []).append(r)
    out = []
    for lot in sorted(by_lot):
        rs = by_lot[lot]
        statistic = str(rs[0].get("statistic") or "phi_eff.p95_abs")
        lo, hi = statistic_range(statistic)
        v = np.array([r["value"] for r in rs], dtype=float)
        mean = float(v.mean())
        sigma = float(v.std(ddof=1)) if v.size > 1 else math.nan
        lower, upper = mean - 3 * sigma, mean + 3 * sigma
        if math.isfinite(sigma):
            lower, upper = max(lower, lo), min(upper, hi)
        outside = (v > upper) | (v < lower) if v.size > 1 else np.zeros(v.size, bool)
        out.append(Trend(lot, tuple(r["run"] for r in rs), tuple(r["recorded_utc"] for r in rs), v, mean, sigma,
                         lower, upper, outside, pane_ids=tuple(str(r.get("pane_id") or "") for r in rs),
                         statistic=statistic, unit=statistic_unit(statistic)))
    return out


#: most run ticks labelled on one panel (every k-th run beyond it)
_MAX_TICKS = 30


def plot_trends(found: list[Trend], *, label: str, max_lots: int = 12):
    """The control charts as one matplotlib Figure: a panel per lot (at most ``max_lots``), runs in order.

    Each panel: the values (line and dots), the mean (solid), the ±3σ limits (dashed, at
    the edge of the statistic's range where they pass it) and the runs beyond them (red,
    ringed). The x axis is the run's order within the lot (integers), each tick labelled
    with the run's pane id (every k-th run when there are more than 30); the y axis
    carries ``label`` and the statistic's unit.
    """
    from matplotlib.figure import Figure

    shown = found[:max_lots]
    n = max(1, len(shown))
    fig = Figure(figsize=(9, 1.6 + 2.6 * n))
    axes = fig.subplots(n, 1, squeeze=False)[:, 0]
    if not shown:
        axes[0].text(0.5, 0.5, "no run with a lot and this statistic", ha="center", va="center",
                     transform=axes[0].transAxes)
        axes[0].set_axis_off()
    for ax, t in zip(axes, shown):
        _plot_lot(ax, t, label)
    if shown:
        axes[-1].set_xlabel("run within the lot, in recording order (tick: pane id)")
    if len(found) > max_lots:
        fig.suptitle(f"first {max_lots} of {len(found)} lots; filter by --lot for the others", fontsize=9)
    fig.tight_layout()
    return fig


def _plot_lot(ax, t: Trend, label: str) -> None:
    """One lot's control chart on ``ax``."""
    x = np.arange(1, t.values.size + 1)
    unit = t.unit
    ax.plot(x, t.values, "-", color="#7a8a99", lw=0.8)
    ax.plot(x[~t.out], t.values[~t.out], "o", ms=3.5, color="#24384f", label="run")
    if t.out.any():
        ax.plot(x[t.out], t.values[t.out], "o", ms=7, mfc="#d62728", mec="#7f0000", label="beyond ±3σ")
    ax.axhline(t.mean, color="#2ca02c", lw=1.2, label=f"mean {t.mean:.4g} {unit}")
    if math.isfinite(t.sigma):
        for y, name, raw in ((t.upper, "+3σ", t.mean + 3 * t.sigma), (t.lower, "−3σ", t.mean - 3 * t.sigma)):
            ax.axhline(y, color="#d62728", ls="--", lw=1)
            text = f" {name}" if y == raw else f" {name}: {y:g} {unit}\n (bound)"
            ax.text(1.0, y, text, va="center", ha="left", fontsize=8, transform=ax.get_yaxis_transform())
    step = max(1, math.ceil(x.size / _MAX_TICKS))
    ticks = x[::step]
    names = [t.pane_ids[i - 1] if i - 1 < len(t.pane_ids) and t.pane_ids[i - 1] else f"run {t.runs[i - 1]}"
             for i in ticks]
    ax.set_xticks(ticks, names, rotation=60 if max(map(len, names)) > 4 or ticks.size > 12 else 0,
                  ha="right" if ticks.size > 12 or max(map(len, names)) > 4 else "center", fontsize=7)
    ax.set_xlim(0.5, x.size + 0.5)
    n_out = int(t.out.sum())
    ax.set_title(f"lot {t.lot}: {t.values.size} runs, σ = {t.sigma:.3g} {unit}, {n_out} beyond the limits  "
                 f"({t.times[0][:10]} … {t.times[-1][:10]})", fontsize=9, loc="left")
    ax.set_ylabel(f"{label} [{unit}]", fontsize=8)
    ax.grid(alpha=0.3)
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi + 0.22 * (hi - lo))  # headroom for the legend above the runs
    ax.legend(fontsize=7, loc="upper left", ncols=3)
