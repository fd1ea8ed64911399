"""the portal: runs uploaded from team instances (instance, remote id, declared logs), officers'
notes and invalidations, refused uploads, and an instance's outbox of runs to upload

Revision ID: 0008
Revises: 0007
Create Date: 2026-11-23 02:08:22.837341
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = "0008"
down_revision = "0007"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "portal_refusals",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("instance_id", sa.Integer(), nullable=True),
        sa.Column("team_id", sa.Integer(), nullable=True),
        sa.Column("remote_run_id", sa.Integer(), nullable=True),
        sa.Column("run_id", sa.Integer(), nullable=True),
        sa.Column("reason", sa.Text(), nullable=False),
        sa.Column("detail", sa.JSON(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.ForeignKeyConstraint(
            ["instance_id"],
            ["team_instances.id"],
            name=op.f("fk_portal_refusals_instance_id_team_instances"),
            ondelete="SET NULL",
        ),
        sa.ForeignKeyConstraint(
            ["run_id"],
            ["runs.id"],
            name=op.f("fk_portal_refusals_run_id_runs"),
            ondelete="SET NULL",
        ),
        sa.ForeignKeyConstraint(
            ["team_id"],
            ["teams.id"],
            name=op.f("fk_portal_refusals_team_id_teams"),
            ondelete="SET NULL",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_portal_refusals")),
    )
    with op.batch_alter_table("portal_refusals", schema=None) as batch_op:
        batch_op.create_index(
            batch_op.f("ix_portal_refusals_created_at"), ["created_at"], unique=False
        )
        batch_op.create_index(
            batch_op.f("ix_portal_refusals_instance_id"), ["instance_id"], unique=False
        )

    op.create_table(
        "portal_uploads",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column(
            "state",
            sa.Enum(
                "pending",
                "uploading",
                "uploaded",
                "refused",
                name="uploadstate",
                native_enum=False,
                create_constraint=False,
                length=16,
            ),
            nullable=False,
        ),
        sa.Column("bytes_sent", sa.BigInteger(), nullable=False),
        sa.Column("bytes_total", sa.BigInteger(), nullable=False),
        sa.Column("attempts", sa.Integer(), nullable=False),
        sa.Column("next_attempt_at", sa.DateTime(), nullable=False),
        sa.Column("error", sa.Text(), nullable=True),
        sa.Column("master_run_id", sa.Integer(), nullable=True),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.Column("uploaded_at", sa.DateTime(), nullable=True),
        sa.ForeignKeyConstraint(
            ["run_id"], ["runs.id"], name=op.f("fk_portal_uploads_run_id_runs"), ondelete="CASCADE"
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_portal_uploads")),
    )
    with op.batch_alter_table("portal_uploads", schema=None) as batch_op:
        batch_op.create_index(batch_op.f("ix_portal_uploads_run_id"), ["run_id"], unique=True)

    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.add_column(sa.Column("instance_id", sa.Integer(), nullable=True))
        batch_op.add_column(sa.Column("remote_run_id", sa.Integer(), nullable=True))
        batch_op.add_column(sa.Column("uploaded_at", sa.DateTime(), nullable=True))
        batch_op.add_column(sa.Column("upload_manifest", sa.JSON(), nullable=True))
        batch_op.add_column(sa.Column("logs_complete_at", sa.DateTime(), nullable=True))
        batch_op.add_column(sa.Column("officer_note", sa.Text(), nullable=True))
        batch_op.add_column(sa.Column("invalidated_at", sa.DateTime(), nullable=True))
        batch_op.add_column(sa.Column("invalid_reason", sa.Text(), nullable=True))
        batch_op.create_index(batch_op.f("ix_runs_instance_id"), ["instance_id"], unique=False)
        batch_op.create_unique_constraint(
            batch_op.f("uq_runs_instance_id"), ["instance_id", "remote_run_id"]
        )
        batch_op.create_foreign_key(
            batch_op.f("fk_runs_instance_id_team_instances"),
            "team_instances",
            ["instance_id"],
            ["id"],
            ondelete="SET NULL",
        )


def downgrade() -> None:
    with op.batch_alter_table("runs", schema=None) as batch_op:
        batch_op.drop_constraint(
            batch_op.f("fk_runs_instance_id_team_instances"), type_="foreignkey"
        )
        batch_op.drop_constraint(batch_op.f("uq_runs_instance_id"), type_="unique")
        batch_op.drop_index(batch_op.f("ix_runs_instance_id"))
        batch_op.drop_column("invalid_reason")
        batch_op.drop_column("invalidated_at")
        batch_op.drop_column("officer_note")
        batch_op.drop_column("logs_complete_at")
        batch_op.drop_column("upload_manifest")
        batch_op.drop_column("uploaded_at")
        batch_op.drop_column("remote_run_id")
        batch_op.drop_column("instance_id")

    with op.batch_alter_table("portal_uploads", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_portal_uploads_run_id"))

    op.drop_table("portal_uploads")
    with op.batch_alter_table("portal_refusals", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_portal_refusals_instance_id"))
        batch_op.drop_index(batch_op.f("ix_portal_refusals_created_at"))

    op.drop_table("portal_refusals")
