"""runs: at most one live or counted run per task, held by the database

Revision ID: 0012
Revises: 0011
Create Date: 2026-11-23 09:00:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0012"
down_revision = "0011"
branch_labels = None
depends_on = None

LIVE = "state IN ('starting', 'running', 'stopping')"
COUNTED = "state = 'finished' AND invalidated_at IS NULL"


def upgrade() -> None:
    # Two starts of one task on two constellations at the same instant could both start before
    # this index: a live run whose task already has a counted or an earlier live run ends in
    # error, with the reason (never deleted).
    op.execute(
        "UPDATE runs SET state = 'error', active_constellation_id = NULL, error = "
        "'a second live run of its task (found by migration 0012)' "
        f"WHERE {LIVE} AND (task_id IN (SELECT task_id FROM runs WHERE {COUNTED}) "
        f"OR id NOT IN (SELECT min(id) FROM runs WHERE {LIVE} GROUP BY task_id))"
    )
    op.drop_index("uq_runs_task_counted", table_name="runs")
    where = sa.text(f"{LIVE} OR ({COUNTED})")
    op.create_index(
        "uq_runs_task_live_or_counted",
        "runs",
        ["task_id"],
        unique=True,
        sqlite_where=where,
        postgresql_where=where,
    )


def downgrade() -> None:
    op.drop_index("uq_runs_task_live_or_counted", table_name="runs")
    counted = sa.text(COUNTED)
    op.create_index(
        "uq_runs_task_counted",
        "runs",
        ["task_id"],
        unique=True,
        sqlite_where=counted,
        postgresql_where=counted,
    )
