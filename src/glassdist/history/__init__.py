"""The results history: every analysis the output stage writes, recorded in a database.

Every ``glassdist analyze``, batch pane, web job and Python-API run (all write through
:func:`glassdist.storage.writer.write_outputs`) adds one row: time, pane, lot, site,
operator, camera, input hashes, the resolved protocol, the verdict with each check, the
statistics per zone, the standard measures, warnings and the output folder. A re-run is a
new row; rows are never changed. ``glassdist history`` lists, filters, exports and charts
them; :func:`history` returns them to Python, and the subpackage itself is callable as it
(``glassdist.history(lot="42")``). See ``docs/user-guide/history.md``.

A record that cannot reach its database (server down, driver missing, folder unwritable)
waits in a local spool and is written, once, by the next run or read that reaches it.

Modules: :mod:`~glassdist.history.models` (the tables), :mod:`~glassdist.history.store`
(where the database is, opening, upgrading, writing), :mod:`~glassdist.history.spool`
(records waiting for their database), :mod:`~glassdist.history.query` (filters, records,
control charts).
"""

from __future__ import annotations

import contextlib
import sys
import types
from typing import TYPE_CHECKING

from .._lazy import lazy_exports
from .store import (
    HistoryUnavailable,
    Location,
    Recorded,
    Recording,
    SpoolFlush,
    data_dir,
    flush_spool,
    locate,
    open_store,
    record,
    record_run,
    spool_dir,
)

# --- typed names for static tools (scripts/lazy_stubs.py writes this block) ---
if TYPE_CHECKING:
    from .query import COLUMNS, HistoryFilter, Trend, plot_trends, query_runs, trends
# --- end of the typed names ---

# the query side (SQLAlchemy, numpy) is imported when first used
__getattr__, __dir__ = lazy_exports(__name__, dict.fromkeys(
    ("COLUMNS", "HistoryFilter", "Trend", "plot_trends", "query_runs", "trends"), ".query"))

__all__ = ["history", "COLUMNS", "HistoryFilter", "HistoryUnavailable", "Location", "Recorded", "Recording",
           "SpoolFlush", "Trend", "data_dir", "flush_spool", "locate", "open_store", "plot_trends", "query_runs",
           "record", "record_run", "read_records", "spool_dir", "trends"]


def history(db=None, *, as_frame=None, **filters):
    """The recorded runs, filtered: a pandas DataFrame when pandas is installed, else a list of dicts.

    Parameters
    ----------
    db : str or path, optional
        Database file or URL (default: ``GLASSDIST_DB``, else the user's data folder;
        see :func:`glassdist.history.locate`).
    as_frame : bool, optional
        True: a DataFrame (needs pandas); False: records; None: a DataFrame if pandas imports.
    **filters
        :class:`HistoryFilter` fields: ``pane_id``, ``lot``, ``site``, ``operator``,
        ``source``, ``verdict`` (PASS, FAIL, none), ``since``, ``until`` (``YYYY-MM-DD``
        or datetime, UTC), ``zone``, ``statistic`` (``'phi_eff.p95_abs'``), ``above``,
        ``below``, ``failed_zone``, ``limit``.

    Returns
    -------
    pandas.DataFrame or list of dict
        One row per run, oldest first, columns :data:`COLUMNS` (``value``: the selected
        statistic, mD). Records that waited in the spool for this database
        (:func:`flush_spool`) are written to it first, where it can be written.

    Raises
    ------
    InputError
        An unknown filter, a bad date or statistic, an unreadable database.

    Examples
    --------
    >>> import glassdist
    >>> runs = glassdist.history(lot="L42", statistic="phi_eff.p95_abs", as_frame=False)  # doctest: +SKIP
    >>> [(r["pane_id"], r["value"]) for r in runs]                                        # doctest: +SKIP
    [('P-1', 38.4), ('P-2', 41.0)]
    """
    from .query import COLUMNS

    records, _ = read_records(db, filters)
    if as_frame is False:
        return records
    try:
        import pandas as pd
    except ImportError:
        if as_frame:
            raise
        return records
    return pd.DataFrame.from_records(records, columns=list(COLUMNS))


def read_records(db, filters: dict) -> tuple[list[dict], SpoolFlush]:
    """The filtered runs as records, after writing what waited in the spool for ``db``; and what that wrote.

    The one reader behind :func:`history`, ``glassdist history`` and the web app's History page.
    """
    from .query import HistoryFilter, query_runs

    flt = HistoryFilter.of(**filters)
    flushed = flush_spool(db)  # a record kept while the database was unreachable is read with the others
    try:
        store = open_store(db)
        with store if store is not None else contextlib.nullcontext():
            records = query_runs(store, flt)
    except HistoryUnavailable:
        raise
    except Exception as exc:  # noqa: BLE001 - a database error is the user's to fix: one line
        from .store import describe_failure

        raise HistoryUnavailable(f"cannot read the history '{locate(db)}': {describe_failure(exc)}") from None
    return records, flushed


class _CallableModule(types.ModuleType):
    """This subpackage, callable as :func:`history`: ``glassdist.history(lot="42")`` reads the runs."""

    def __call__(self, db=None, *, as_frame=None, **filters):
        return history(db, as_frame=as_frame, **filters)


sys.modules[__name__].__class__ = _CallableModule
