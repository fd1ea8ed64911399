"""constellations: room in `state` for `terminate_incomplete` (a machine a terminate left dirty)

Revision ID: 0016
Revises: 0015
Create Date: 2026-11-27 22:00:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0016"
down_revision = "0015"
branch_labels = None
depends_on = None

STATES = (
    "pending",
    "launching",
    "ready",
    "error",
    "terminating",
    "terminated",
)


def _state(*extra: str, length: int) -> sa.Enum:
    return sa.Enum(*STATES, *extra, name="constellationstate", native_enum=False, length=length)


def upgrade() -> None:
    with op.batch_alter_table("constellations", schema=None) as batch_op:
        batch_op.alter_column(
            "state",
            existing_type=_state(length=16),
            type_=_state("terminate_incomplete", length=24),
            existing_nullable=False,
        )


def downgrade() -> None:
    # A constellation left incomplete goes back to `error`, the old way of saying "look at it".
    op.execute(
        "UPDATE constellations SET state = 'error' WHERE state = 'terminate_incomplete'"
    )
    with op.batch_alter_table("constellations", schema=None) as batch_op:
        batch_op.alter_column(
            "state",
            existing_type=_state("terminate_incomplete", length=24),
            type_=_state(length=16),
            existing_nullable=False,
        )
