"""runs and constellations: a stable error code; runs: when one went to needs review

Revision ID: 0017
Revises: 0016
Create Date: 2026-11-27 22:00:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0017"
down_revision = "0016"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("runs") as batch:
        batch.add_column(sa.Column("error_code", sa.String(length=32), nullable=True))
        batch.add_column(sa.Column("review_since", sa.DateTime(), nullable=True))
    with op.batch_alter_table("constellations") as batch:
        batch.add_column(sa.Column("error_code", sa.String(length=32), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("constellations") as batch:
        batch.drop_column("error_code")
    with op.batch_alter_table("runs") as batch:
        batch.drop_column("review_since")
        batch.drop_column("error_code")
