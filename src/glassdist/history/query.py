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
           "parse_statistic"]

_STAT_RE = re.compile(r"^([a-z_]+)\.([A-Za-z0-9_]+)$")
#: columns of a history record, in order (``value``: the selected statistic)
COLUMNS = ("run", "recorded_utc", "source", "pane_id", "lot", "site", "operator", "verdict", "spec_name", "zone",
           "statistic", "value", "phi_eff_p95_abs_mD", "phi_shear_p95_abs_mD", "valid_percent", "method",
           "pitch_mm", "distance_m", "sigma_mm", "detrend_degree", "camera", "image", "image_sha256", "exit_code",
           "warnings", "out_dir", "job")


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
    keys = {(zone, channel, stat), (REGION, "phi_eff", "p95_abs"), (REGION, "phi_shear", "p95_abs")}
    # time and warnings as stored (text on SQLite): turned into ISO text and a list below, without a parse per row
    cols = [Run.id, type_coerce(Run.recorded_utc, String).label("recorded_utc"), Run.source, Run.pane_id, Run.lot, Run.site, Run.operator, Run.verdict,
            Run.spec_name, Run.valid_percent, Run.method, Run.pitch_mm, Run.distance_m, Run.sigma_mm,
            Run.detrend_degree, Run.camera, Run.image, Run.image_sha256, Run.exit_code, type_coerce(Run.warnings, String).label("warnings"), Run.out_dir,
            Run.job]
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
        The statistic of each run.
    mean, sigma : float
        Centre line and sample standard deviation (``nan`` for fewer than two runs).
    lower, upper : float
        ``mean - 3 sigma``, ``mean + 3 sigma``.
    out : ndarray of bool
        Runs beyond a control limit.
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

    def to_dict(self) -> dict:
        return {"lot": self.lot, "mean": self.mean, "sigma": self.sigma, "lower": self.lower, "upper": self.upper,
                "runs": list(self.runs), "out_of_control": [r for r, o in zip(self.runs, self.out) if o]}


def trends(records: list[dict]) -> list[Trend]:
    """One :class:`Trend` per lot of the records (runs without a value or a lot are left out), by lot name."""
    by_lot: dict[str, list[dict]] = {}
    for r in records:
        if r.get("value") is not None and r.get("lot"):
            by_lot.setdefault(str(r["lot"]), []).append(r)
    out = []
    for lot in sorted(by_lot):
        rs = by_lot[lot]
        v = np.array([r["value"] for r in rs], dtype=float)
        mean = float(v.mean())
        sigma = float(v.std(ddof=1)) if v.size > 1 else math.nan
        lower, upper = mean - 3 * sigma, mean + 3 * sigma
        outside = (v > upper) | (v < lower) if v.size > 1 else np.zeros(v.size, bool)
        out.append(Trend(lot, tuple(r["run"] for r in rs), tuple(r["recorded_utc"] for r in rs), v, mean, sigma,
                         lower, upper, outside))
    return out


def plot_trends(found: list[Trend], *, label: str, max_lots: int = 12):
    """The control charts as one matplotlib Figure: a panel per lot (at most ``max_lots``), runs in order.

    Each panel: the values (line and dots), the mean (solid), the ±3σ limits (dashed) and
    the runs beyond them (red, ringed). The x axis is the run's order within the lot, its
    recording date under the first and last tick.
    """
    from matplotlib.figure import Figure

    shown = found[:max_lots]
    n = max(1, len(shown))
    fig = Figure(figsize=(9, 1.2 + 2.2 * n))
    axes = fig.subplots(n, 1, squeeze=False)[:, 0]
    if not shown:
        axes[0].text(0.5, 0.5, "no run with a lot and this statistic", ha="center", va="center",
                     transform=axes[0].transAxes)
        axes[0].set_axis_off()
    for ax, t in zip(axes, shown):
        x = np.arange(1, t.values.size + 1)
        ax.plot(x, t.values, "-", color="#7a8a99", lw=0.8)
        ax.plot(x[~t.out], t.values[~t.out], "o", ms=3.5, color="#24384f", label="run")
        if t.out.any():
            ax.plot(x[t.out], t.values[t.out], "o", ms=7, mfc="#d62728", mec="#7f0000", label="beyond ±3σ")
        ax.axhline(t.mean, color="#2ca02c", lw=1.2, label=f"mean {t.mean:.4g}")
        if math.isfinite(t.sigma):
            for y in (t.lower, t.upper):
                ax.axhline(y, color="#d62728", ls="--", lw=1)
            ax.text(1.0, t.upper, " +3σ", va="center", ha="left", fontsize=8, transform=ax.get_yaxis_transform())
            ax.text(1.0, t.lower, " −3σ", va="center", ha="left", fontsize=8, transform=ax.get_yaxis_transform())
        n_out = int(t.out.sum())
        ax.set_title(f"lot {t.lot}: {t.values.size} runs, σ = {t.sigma:.3g}, {n_out} beyond the limits  "
                     f"({t.times[0][:10]} … {t.times[-1][:10]})", fontsize=9, loc="left")
        ax.set_ylabel(label, fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper left", ncols=3)
    axes[-1].set_xlabel("run within the lot (recording order)")
    if len(found) > max_lots:
        fig.suptitle(f"first {max_lots} of {len(found)} lots; filter by --lot for the others", fontsize=9)
    fig.tight_layout()
    return fig
