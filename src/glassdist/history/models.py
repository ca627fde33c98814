"""The history's tables as SQLAlchemy 2.x declarative models (schema version :data:`SCHEMA_REVISION`).

One row of :class:`Run` per analysis ever written by the output stage; its verdict's checks
(:class:`CheckRow`) and its statistics per zone (:class:`StatisticRow`: one value per zone,
channel and statistic, so that any of them can be filtered and charted by an index) hang
from it. Rows are only ever inserted: a re-run of the same pane is a new :class:`Run`.

The tables are created and upgraded by the Alembic revisions in
``glassdist/history/migrations/versions/`` (:func:`glassdist.history.store.open_store`),
never from these classes: a revision states its own tables, so that an old database is
brought forward step by step.
"""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import JSON, Boolean, DateTime, Float, ForeignKey, Index, Integer, String, Text
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

__all__ = ["Base", "Run", "CheckRow", "StatisticRow", "SCHEMA_REVISION", "REGION"]

#: Alembic revision of the schema these models describe (the newest in ``migrations/versions``)
SCHEMA_REVISION = "0002"

#: zone name of the statistics over the whole analysed region (a specification's zones keep their names)
REGION = "all"


class Base(DeclarativeBase):
    """Declarative base of the history's tables."""


class Run(Base):
    """One recorded analysis: who, what, with which protocol, and what it gave.

    Lengths in mm, L in m, optical power in mD (as in ``summary.json``).
    """

    __tablename__ = "runs"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    # SHA-256 of the record's content: a record written again (from the spool) is recognised, never duplicated
    record_id: Mapped[str | None] = mapped_column(String(64), unique=True, index=True)
    recorded_utc: Mapped[datetime] = mapped_column(DateTime, index=True)
    source: Mapped[str] = mapped_column(String(16))  # cli, batch, web, api
    job: Mapped[str | None] = mapped_column(String(400))  # web job id, or the batch's folder
    pane_id: Mapped[str | None] = mapped_column(String(200), index=True)
    lot: Mapped[str | None] = mapped_column(String(200), index=True)
    site: Mapped[str | None] = mapped_column(String(200), index=True)
    operator: Mapped[str | None] = mapped_column(String(200))
    camera: Mapped[str | None] = mapped_column(String(200))
    image: Mapped[str | None] = mapped_column(Text)
    image_sha256: Mapped[str | None] = mapped_column(String(64), index=True)
    reference: Mapped[str | None] = mapped_column(Text)
    reference_sha256: Mapped[str | None] = mapped_column(String(64))
    method: Mapped[str | None] = mapped_column(String(16))
    pattern: Mapped[str | None] = mapped_column(String(16))
    pitch_mm: Mapped[float | None] = mapped_column(Float)
    distance_m: Mapped[float | None] = mapped_column(Float)
    sigma_mm: Mapped[float | None] = mapped_column(Float)
    detrend_degree: Mapped[int | None] = mapped_column(Integer)
    protocol: Mapped[dict | None] = mapped_column(JSON)
    verdict: Mapped[str | None] = mapped_column(String(8), index=True)  # PASS, FAIL, or None without a spec
    spec_name: Mapped[str | None] = mapped_column(String(400))
    spec_sha256: Mapped[str | None] = mapped_column(String(64))
    exit_code: Mapped[int] = mapped_column(Integer)
    valid_percent: Mapped[float | None] = mapped_column(Float)  # the measured share (summary's measured_percent)
    trusted_percent: Mapped[float | None] = mapped_column(Float)  # the trusted share, that specifications judge
    measures: Mapped[dict | None] = mapped_column(JSON)
    warnings: Mapped[list | None] = mapped_column(JSON)
    out_dir: Mapped[str | None] = mapped_column(Text)
    glassdist_version: Mapped[str | None] = mapped_column(String(40))

    checks: Mapped[list[CheckRow]] = relationship(back_populates="run", order_by="CheckRow.id")
    statistics: Mapped[list[StatisticRow]] = relationship(back_populates="run", order_by="StatisticRow.id")


class CheckRow(Base):
    """One check of a run's verdict (``summary.json`` ``verdict.checks``); ``zone`` when the criterion names one."""

    __tablename__ = "checks"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"), index=True)
    criterion: Mapped[str] = mapped_column(Text)
    zone: Mapped[str | None] = mapped_column(String(200))
    value: Mapped[float | None] = mapped_column(Float)
    limit: Mapped[float | None] = mapped_column(Float)
    unit: Mapped[str | None] = mapped_column(String(16))
    passed: Mapped[bool] = mapped_column(Boolean)
    note: Mapped[str | None] = mapped_column(Text)

    run: Mapped[Run] = relationship(back_populates="checks")


class StatisticRow(Base):
    """One statistic of one channel over one zone (:data:`REGION` for the whole analysed region), mD or %."""

    __tablename__ = "statistics"
    __table_args__ = (Index("ix_statistics_key", "zone", "channel", "statistic", "run_id"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"), index=True)
    zone: Mapped[str] = mapped_column(String(200))
    channel: Mapped[str] = mapped_column(String(32))
    statistic: Mapped[str] = mapped_column(String(32))
    value: Mapped[float] = mapped_column(Float)

    run: Mapped[Run] = relationship(back_populates="statistics")
