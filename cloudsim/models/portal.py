"""The portal: results a master refused from its team instances, and on an instance the
outbox of finished runs waiting to reach the master."""

from __future__ import annotations

import enum
from datetime import datetime
from typing import TYPE_CHECKING, Any

from sqlalchemy import JSON, BigInteger, ForeignKey, Text
from sqlalchemy.orm import Mapped, mapped_column, relationship

from cloudsim.models.base import Base, UTCDateTime, str_enum, utcnow

if TYPE_CHECKING:
    from cloudsim.models.competition import Run
    from cloudsim.models.team_instances import TeamInstance


class PortalRefusal(Base):
    """A result a team instance sent that the master refused, and why (shown to officers)."""

    __tablename__ = "portal_refusals"

    id: Mapped[int] = mapped_column(primary_key=True)
    instance_id: Mapped[int | None] = mapped_column(
        ForeignKey("team_instances.id", ondelete="SET NULL"), index=True
    )
    # the team the instance served when it sent it (None: a spare)
    team_id: Mapped[int | None] = mapped_column(ForeignKey("teams.id", ondelete="SET NULL"))
    remote_run_id: Mapped[int | None] = mapped_column()
    # the master's row, when the refusal concerns a log of a run it accepted
    run_id: Mapped[int | None] = mapped_column(ForeignKey("runs.id", ondelete="SET NULL"))
    reason: Mapped[str] = mapped_column(Text)
    # what was sent, briefly: task key, team, times, file name (never a log's content)
    detail: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow, index=True)

    instance: Mapped[TeamInstance | None] = relationship()

    def __repr__(self) -> str:
        return f"<PortalRefusal {self.id} instance={self.instance_id} {self.reason[:40]!r}>"


class UploadState(enum.StrEnum):
    """Where a finished run's upload to the master stands (on a team instance)."""

    PENDING = "pending"
    UPLOADING = "uploading"
    UPLOADED = "uploaded"
    REFUSED = "refused"


class PortalUpload(Base):
    """On a team instance: one finished run to send to the master's portal (the outbox).

    Sent oldest first; a failure waits `next_attempt_at` (exponential backoff) and holds the
    ones after it, so they arrive in order; a refusal is final and holds nothing.
    """

    __tablename__ = "portal_uploads"

    id: Mapped[int] = mapped_column(primary_key=True)
    run_id: Mapped[int] = mapped_column(
        ForeignKey("runs.id", ondelete="CASCADE"), unique=True, index=True
    )
    state: Mapped[UploadState] = mapped_column(str_enum(UploadState), default=UploadState.PENDING)
    bytes_sent: Mapped[int] = mapped_column(BigInteger, default=0)  # logs' bytes the master has
    bytes_total: Mapped[int] = mapped_column(BigInteger, default=0)
    attempts: Mapped[int] = mapped_column(default=0)  # failed tries since the last progress
    next_attempt_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    error: Mapped[str | None] = mapped_column(Text)  # the last failure, or the refusal's reason
    master_run_id: Mapped[int | None] = mapped_column()  # the run's id on the master
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    uploaded_at: Mapped[datetime | None] = mapped_column(UTCDateTime)

    run: Mapped[Run] = relationship()

    @property
    def percent(self) -> int:
        """Return how much of the logs the master has, in percent."""
        return 100 if not self.bytes_total else int(100 * self.bytes_sent / self.bytes_total)

    def __repr__(self) -> str:
        return f"<PortalUpload {self.id} run={self.run_id} {self.state}>"
