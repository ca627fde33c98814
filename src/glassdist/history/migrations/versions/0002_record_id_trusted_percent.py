"""Each run's record id (the SHA-256 of its content, unique) and its trusted share.

``record_id`` lets a record kept in the spool while the database could not be reached be
written later exactly once; ``trusted_percent`` is the share of the analysed region a
specification judges (``trusted_percent`` of ``summary.json``), beside ``valid_percent``
(the measured share). Runs recorded before this revision keep both empty.

Revision ID: 0002
Revises: 0001
"""

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade():
    op.add_column("runs", sa.Column("record_id", sa.String(64)))
    op.add_column("runs", sa.Column("trusted_percent", sa.Float))
    op.create_index("ix_runs_record_id", "runs", ["record_id"], unique=True)


def downgrade():
    op.drop_index("ix_runs_record_id", "runs")
    with op.batch_alter_table("runs") as batch:
        batch.drop_column("trusted_percent")
        batch.drop_column("record_id")
