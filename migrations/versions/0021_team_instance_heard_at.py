"""team instances: when the master last heard from each (an answered check or sync)

Revision ID: 0021
Revises: 0020
Create Date: 2026-11-28 01:20:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0021"
down_revision = "0020"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("team_instances") as batch:
        batch.add_column(sa.Column("heard_at", sa.DateTime(), nullable=True))
    # a ready instance answered its last check: that is the last time it was heard from
    op.execute("UPDATE team_instances SET heard_at = checked_at WHERE state = 'ready'")


def downgrade() -> None:
    with op.batch_alter_table("team_instances") as batch:
        batch.drop_column("heard_at")
