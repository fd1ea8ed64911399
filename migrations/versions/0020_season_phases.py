"""season phases: the phases table and each task's phase

Revision ID: 0020
Revises: 0019
Create Date: 2026-11-28 01:00:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0020"
down_revision = "0019"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "phases",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=60), nullable=False),
        sa.Column("position", sa.Integer(), nullable=False),
        sa.Column("window_start", sa.DateTime(), nullable=False),
        sa.Column("window_stop", sa.DateTime(), nullable=False),
        sa.Column("time_zone", sa.String(length=64), nullable=False),
        sa.Column("worlds", sa.JSON(), nullable=False),
        sa.Column("timeout_s", sa.Integer(), nullable=False),
        sa.Column("latency_ms", sa.Integer(), nullable=False),
        sa.Column("uplink_bits", sa.BigInteger(), nullable=False),
        sa.Column("downlink_bits", sa.BigInteger(), nullable=False),
        sa.Column("entry_phase_id", sa.Integer(), nullable=True),
        sa.Column("entry_min_score", sa.Integer(), nullable=True),
        sa.Column("max_runs_per_task", sa.Integer(), nullable=True),
        sa.Column("max_runs_per_day", sa.Integer(), nullable=True),
        sa.Column("max_runs_total", sa.Integer(), nullable=True),
        sa.Column("max_runs_at_once", sa.Integer(), nullable=True),
        sa.Column("scores_hidden", sa.Boolean(), nullable=False),
        sa.Column("revealed_at", sa.DateTime(), nullable=True),
        sa.Column("counts_in_ranking", sa.Boolean(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.ForeignKeyConstraint(
            ["entry_phase_id"],
            ["phases.id"],
            name=op.f("fk_phases_entry_phase_id_phases"),
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_phases")),
        sa.UniqueConstraint("name", name=op.f("uq_phases_name")),
    )
    if op.get_bind().dialect.name == "sqlite":
        # A batch copy of tasks would drop the old table, and with it (ON DELETE CASCADE,
        # foreign keys on) every run: SQLite can add a referencing column in place instead.
        op.execute(
            "ALTER TABLE tasks ADD COLUMN phase_id INTEGER"
            " REFERENCES phases (id)"
        )
    else:
        op.add_column("tasks", sa.Column("phase_id", sa.Integer(), nullable=True))
        op.create_foreign_key(
            op.f("fk_tasks_phase_id_phases"),
            "tasks",
            "phases",
            ["phase_id"],
            ["id"],
        )
    op.create_index(op.f("ix_tasks_phase_id"), "tasks", ["phase_id"], unique=False)


def downgrade() -> None:
    op.drop_index(op.f("ix_tasks_phase_id"), table_name="tasks")
    if op.get_bind().dialect.name == "sqlite":
        op.execute("ALTER TABLE tasks DROP COLUMN phase_id")  # SQLite 3.35+, in place
    else:
        op.drop_constraint(op.f("fk_tasks_phase_id_phases"), "tasks", type_="foreignkey")
        op.drop_column("tasks", "phase_id")
    op.drop_table("phases")
