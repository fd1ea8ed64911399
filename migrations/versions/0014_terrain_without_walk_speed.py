"""worlds: terrain patches without `walk_speed` (it scaled the balance harness's walk, now gone)

Revision ID: 0014
Revises: 0013
Create Date: 2026-11-23 10:00:00
"""

from __future__ import annotations

import copy
from datetime import UTC, datetime
from typing import Any

import sqlalchemy as sa
from alembic import op
from drcsim.worlds import check_document, document_digest

revision = "0014"
down_revision = "0013"
branch_labels = None
depends_on = None

worlds = sa.table(
    "worlds",
    sa.column("id", sa.Integer),
    sa.column("version", sa.Integer),
    sa.column("digest", sa.String),
    sa.column("document", sa.JSON),
    sa.column("updated_at", sa.DateTime),
)


def migrated(document: dict[str, Any]) -> dict[str, Any] | None:
    """Return `document` without `walk_speed` in its terrain and overrides; None if it had none."""
    new = copy.deepcopy(document)
    patches = list(new.get("terrain", []))
    for config in new.get("configs", {}).values():
        patches += list(config.get("terrain", {}).values())
    changed = False
    for patch in patches:
        if isinstance(patch, dict) and "walk_speed" in patch:
            del patch["walk_speed"]
            changed = True
    return new if changed else None


def upgrade() -> None:
    # The walker walks at the speed its gait and the ground give it: a stored world's
    # `walk_speed` means nothing any more, so it goes (a new version of the document).
    connection = op.get_bind()
    now = datetime.now(UTC).replace(tzinfo=None)  # stored as naive UTC, as UTCDateTime does
    rows = connection.execute(sa.select(worlds.c.id, worlds.c.version, worlds.c.document)).all()
    for row in rows:
        document = migrated(row.document)
        if document is None:
            continue
        check_document(document)
        connection.execute(
            worlds.update()
            .where(worlds.c.id == row.id)
            .values(
                version=row.version + 1,
                digest=document_digest(document),
                document=document,
                updated_at=now,
            )
        )


def downgrade() -> None:
    # `walk_speed` is not restored: nothing reads it.
    pass
