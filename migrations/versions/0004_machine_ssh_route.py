"""machine ssh route

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-22 20:30:00.000000
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = '0004'
down_revision = '0003'
branch_labels = None
depends_on = None


def upgrade() -> None:
    # How the controller reaches each machine, recorded when it is created (rows made before
    # this revision get theirs from the provider the first time they are needed).
    with op.batch_alter_table('machines', schema=None) as batch_op:
        batch_op.add_column(sa.Column('ssh_route', sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('machines', schema=None) as batch_op:
        batch_op.drop_column('ssh_route')
