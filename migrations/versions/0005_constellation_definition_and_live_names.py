"""constellation definition stored at launch; names unique among live constellations only

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-22 21:10:00.000000
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None

LIVE_NAME = sa.text("state != 'terminated'")


def upgrade() -> None:
    # The kind as launched, so jobs stop re-reading (possibly changed) YAML; rows made before
    # this revision have none and are read from the kind's file, as before.
    with op.batch_alter_table("constellations", schema=None) as batch_op:
        batch_op.add_column(sa.Column("definition", sa.JSON(), nullable=True))
        # A terminated constellation keeps its name as history; the name can be launched again.
        batch_op.drop_constraint("uq_constellations_name", type_="unique")
    op.create_index(
        "uq_constellations_live_name",
        "constellations",
        ["name"],
        unique=True,
        sqlite_where=LIVE_NAME,
        postgresql_where=LIVE_NAME,
    )


def downgrade() -> None:
    # Under the old rule only the newest constellation of a name keeps it; older ones (all
    # terminated) are renamed NAME-ID rather than lost.
    op.execute(
        "UPDATE constellations SET name = name || '-' || CAST(id AS VARCHAR(20)) WHERE id NOT IN "
        "(SELECT max(id) FROM constellations GROUP BY name)"
    )
    op.drop_index("uq_constellations_live_name", table_name="constellations")
    with op.batch_alter_table("constellations", schema=None) as batch_op:
        batch_op.create_unique_constraint("uq_constellations_name", ["name"])
        batch_op.drop_column("definition")
