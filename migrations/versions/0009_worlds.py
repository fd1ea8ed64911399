"""world definitions as data (run configurations and scoring rules), seeded from drcsim's shipped worlds

Revision ID: 0009
Revises: 0008
Create Date: 2026-11-23 02:00:00
"""

from __future__ import annotations

from datetime import UTC, datetime

import sqlalchemy as sa
from alembic import op
from drcsim.worlds import WORLD_NAMES, document_digest, shipped_document

revision = "0009"
down_revision = "0008"
branch_labels = None
depends_on = None


def upgrade() -> None:
    worlds = op.create_table(
        "worlds",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=64), nullable=False),
        sa.Column("version", sa.Integer(), nullable=False),
        sa.Column("digest", sa.String(length=64), nullable=False),
        sa.Column("document", sa.JSON(), nullable=False),
        sa.Column("updated_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_worlds")),
        sa.UniqueConstraint("name", name=op.f("uq_worlds_name")),
    )
    # the worlds the simulator ships with, as this release of drcsim has them (version 1)
    now = datetime.now(UTC).replace(tzinfo=None)  # stored as naive UTC, as UTCDateTime does
    rows = []
    for name in WORLD_NAMES:
        document = shipped_document(name)
        rows.append(
            {
                "name": name,
                "version": 1,
                "digest": document_digest(document),
                "document": document,
                "updated_at": now,
            }
        )
    op.bulk_insert(worlds, rows)


def downgrade() -> None:
    op.drop_table("worlds")
