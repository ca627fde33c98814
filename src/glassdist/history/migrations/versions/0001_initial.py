"""The first schema: runs, their checks and their statistics per zone.

Revision ID: 0001
Revises:
"""

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None


def upgrade():
    op.create_table(
        "runs",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("recorded_utc", sa.DateTime, nullable=False),
        sa.Column("source", sa.String(16), nullable=False),
        sa.Column("job", sa.String(400)),
        sa.Column("pane_id", sa.String(200)),
        sa.Column("lot", sa.String(200)),
        sa.Column("site", sa.String(200)),
        sa.Column("operator", sa.String(200)),
        sa.Column("camera", sa.String(200)),
        sa.Column("image", sa.Text),
        sa.Column("image_sha256", sa.String(64)),
        sa.Column("reference", sa.Text),
        sa.Column("reference_sha256", sa.String(64)),
        sa.Column("method", sa.String(16)),
        sa.Column("pattern", sa.String(16)),
        sa.Column("pitch_mm", sa.Float),
        sa.Column("distance_m", sa.Float),
        sa.Column("sigma_mm", sa.Float),
        sa.Column("detrend_degree", sa.Integer),
        sa.Column("protocol", sa.JSON),
        sa.Column("verdict", sa.String(8)),
        sa.Column("spec_name", sa.String(400)),
        sa.Column("spec_sha256", sa.String(64)),
        sa.Column("exit_code", sa.Integer, nullable=False),
        sa.Column("valid_percent", sa.Float),
        sa.Column("measures", sa.JSON),
        sa.Column("warnings", sa.JSON),
        sa.Column("out_dir", sa.Text),
        sa.Column("glassdist_version", sa.String(40)),
    )
    for col in ("recorded_utc", "pane_id", "lot", "site", "image_sha256", "verdict"):
        op.create_index(f"ix_runs_{col}", "runs", [col])
    op.create_table(
        "checks",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("run_id", sa.Integer, sa.ForeignKey("runs.id"), nullable=False),
        sa.Column("criterion", sa.Text, nullable=False),
        sa.Column("zone", sa.String(200)),
        sa.Column("value", sa.Float),
        sa.Column("limit", sa.Float),
        sa.Column("unit", sa.String(16)),
        sa.Column("passed", sa.Boolean, nullable=False),
        sa.Column("note", sa.Text),
    )
    op.create_index("ix_checks_run_id", "checks", ["run_id"])
    op.create_table(
        "statistics",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("run_id", sa.Integer, sa.ForeignKey("runs.id"), nullable=False),
        sa.Column("zone", sa.String(200), nullable=False),
        sa.Column("channel", sa.String(32), nullable=False),
        sa.Column("statistic", sa.String(32), nullable=False),
        sa.Column("value", sa.Float, nullable=False),
    )
    op.create_index("ix_statistics_run_id", "statistics", ["run_id"])
    op.create_index("ix_statistics_key", "statistics", ["zone", "channel", "statistic", "run_id"])


def downgrade():
    op.drop_table("statistics")
    op.drop_table("checks")
    op.drop_table("runs")
