"""runs: at most one finished, not invalidated run per task, held by the database

Revision ID: 0011
Revises: 0010
Create Date: 2026-11-23 06:30:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0011"
down_revision = "0010"
branch_labels = None
depends_on = None

COUNTED = sa.text("state = 'finished' AND invalidated_at IS NULL")


def upgrade() -> None:
    # Two uploads at the same instant could store two counted runs of one task before this
    # index: the later ones are invalidated (with the reason, for officers), never deleted.
    op.execute(
        "UPDATE runs SET invalidated_at = CURRENT_TIMESTAMP, invalid_reason = "
        "'a second finished run of its task (found by migration 0011)' "
        "WHERE state = 'finished' AND invalidated_at IS NULL AND id NOT IN "
        "(SELECT min(id) FROM runs WHERE state = 'finished' AND invalidated_at IS NULL "
        "GROUP BY task_id)"
    )
    op.create_index(
        "uq_runs_task_counted",
        "runs",
        ["task_id"],
        unique=True,
        sqlite_where=COUNTED,
        postgresql_where=COUNTED,
    )


def downgrade() -> None:
    op.drop_index("uq_runs_task_counted", table_name="runs")
