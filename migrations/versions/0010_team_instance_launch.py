"""team instances: the constellation launched through each one (what the master last saw of it)

Revision ID: 0010
Revises: 0009
Create Date: 2026-11-23 02:20:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0010"
down_revision = "0009"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("team_instances") as batch:
        batch.add_column(sa.Column("launch", sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("team_instances") as batch:
        batch.drop_column("launch")
