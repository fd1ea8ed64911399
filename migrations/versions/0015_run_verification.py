"""runs: what re-simulating a finished run from its own logs found (verification)

Revision ID: 0015
Revises: 0014
Create Date: 2026-11-27 22:00:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0015"
down_revision = "0014"
branch_labels = None
depends_on = None


def upgrade() -> None:
    # Every run starts unverified (NULL): the verification sweep replays the finished ones.
    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.add_column(sa.Column("verification", sa.String(length=16), nullable=True))
        batch_op.add_column(sa.Column("verification_reason", sa.Text(), nullable=True))
        batch_op.add_column(sa.Column("verified_at", sa.DateTime(), nullable=True))
        batch_op.create_index(batch_op.f("ix_runs_verification"), ["verification"], unique=False)


def downgrade() -> None:
    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_runs_verification"))
        batch_op.drop_column("verified_at")
        batch_op.drop_column("verification_reason")
        batch_op.drop_column("verification")
