"""team instances (the CloudSim a master deployed for each team, its health and sync); tasks copied from a master

Revision ID: 0007
Revises: 0006
Create Date: 2026-11-22 23:45:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "team_instances",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=63), nullable=False),
        sa.Column("team_id", sa.Integer(), nullable=True),
        sa.Column("constellation_id", sa.Integer(), nullable=False),
        sa.Column(
            "state",
            sa.Enum(
                "deploying",
                "ready",
                "unreachable",
                "error",
                "terminated",
                name="instancestate",
                native_enum=False,
                create_constraint=False,
                length=16,
            ),
            nullable=False,
        ),
        sa.Column("url", sa.String(length=255), nullable=True),
        sa.Column("cert_fingerprint", sa.String(length=64), nullable=True),
        sa.Column("version", sa.String(length=64), nullable=True),
        sa.Column("health", sa.JSON(), nullable=False),
        sa.Column("error", sa.Text(), nullable=True),
        sa.Column("checked_at", sa.DateTime(), nullable=True),
        sa.Column("last_sync_at", sa.DateTime(), nullable=True),
        sa.Column("sync_error", sa.Text(), nullable=True),
        sa.Column("sync_report", sa.JSON(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.ForeignKeyConstraint(
            ["constellation_id"],
            ["constellations.id"],
            name=op.f("fk_team_instances_constellation_id_constellations"),
            ondelete="CASCADE",
        ),
        sa.ForeignKeyConstraint(
            ["team_id"], ["teams.id"], name=op.f("fk_team_instances_team_id_teams")
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_team_instances")),
    )
    with op.batch_alter_table("team_instances", schema=None) as batch_op:
        batch_op.create_index(
            batch_op.f("ix_team_instances_constellation_id"), ["constellation_id"], unique=False
        )
        batch_op.create_index(batch_op.f("ix_team_instances_team_id"), ["team_id"], unique=False)
    with op.batch_alter_table("tasks", schema=None) as batch_op:
        batch_op.add_column(sa.Column("master_key", sa.String(length=32), nullable=True))
        batch_op.create_unique_constraint(batch_op.f("uq_tasks_master_key"), ["master_key"])


def downgrade() -> None:
    with op.batch_alter_table("tasks", schema=None) as batch_op:
        batch_op.drop_constraint(batch_op.f("uq_tasks_master_key"), type_="unique")
        batch_op.drop_column("master_key")
    with op.batch_alter_table("team_instances", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_team_instances_team_id"))
        batch_op.drop_index(batch_op.f("ix_team_instances_constellation_id"))
    op.drop_table("team_instances")
