"""World definitions: each task world's run configurations and scoring rules, as data."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import JSON, Connection, String, Table, event
from sqlalchemy.orm import Mapped, mapped_column

from cloudsim.models.base import Base, UTCDateTime, utcnow


class World(Base):
    """A world document (drcsim's format) as this CloudSim holds it; runs are built from it."""

    __tablename__ = "worlds"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    # bumped by every change of the document; an instance keeps its master's number
    version: Mapped[int] = mapped_column(default=1)
    digest: Mapped[str] = mapped_column(String(64))  # SHA-256 of the canonical JSON
    document: Mapped[dict[str, Any]] = mapped_column(JSON)
    updated_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)


@event.listens_for(World.__table__, "after_create")
def _seed_shipped(table: Table, connection: Connection, **_: Any) -> None:
    """Fill a table made by create_all (tests, `make run`) as the migration fills it."""
    from drcsim.worlds import WORLD_NAMES, document_digest, shipped_document

    documents = [shipped_document(name) for name in WORLD_NAMES]
    connection.execute(
        table.insert(),
        [
            {
                "name": d["name"],
                "version": 1,
                "digest": document_digest(d),
                "document": d,
                "updated_at": utcnow(),
            }
            for d in documents
        ],
    )
