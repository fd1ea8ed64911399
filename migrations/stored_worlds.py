"""Rewrite the world documents stored in the database, for migrations that change their format."""

from __future__ import annotations

from collections.abc import Callable
from datetime import UTC, datetime
from typing import Any

import sqlalchemy as sa
from alembic import op
from drcsim.worlds import document_digest

WORLDS = sa.table(
    "worlds",
    sa.column("id", sa.Integer),
    sa.column("name", sa.String),
    sa.column("version", sa.Integer),
    sa.column("digest", sa.String),
    sa.column("document", sa.JSON),
    sa.column("updated_at", sa.DateTime),
)


def rewrite(change: Callable[[str, dict[str, Any]], dict[str, Any] | None]) -> None:
    """Store change(name, document) as each world's next version, where it returns one.

    Not checked against drcsim's schema: that is today's, and a later migration may still
    have to bring the document up to it.
    """
    connection = op.get_bind()
    now = datetime.now(UTC).replace(tzinfo=None)  # stored as naive UTC, as UTCDateTime does
    rows = connection.execute(
        sa.select(WORLDS.c.id, WORLDS.c.name, WORLDS.c.version, WORLDS.c.document)
    ).all()
    for row in rows:
        document = change(row.name, row.document)
        if document is not None:
            connection.execute(
                WORLDS.update()
                .where(WORLDS.c.id == row.id)
                .values(
                    version=row.version + 1,
                    digest=document_digest(document),
                    document=document,
                    updated_at=now,
                )
            )
