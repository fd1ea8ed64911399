"""Team instances: the CloudSim a master deployed for a team (or as a spare), and its health."""

from __future__ import annotations

import enum
from datetime import datetime
from typing import TYPE_CHECKING, Any

from sqlalchemy import JSON, ForeignKey, String, Text
from sqlalchemy.orm import Mapped, mapped_column, relationship

from cloudsim.models.base import Base, UTCDateTime, str_enum, utcnow

if TYPE_CHECKING:
    from cloudsim.models.machines import Constellation
    from cloudsim.models.people import Team


class InstanceState(enum.StrEnum):
    """Life cycle of a team instance (set only by cloudsim.team_instances.lifecycle)."""

    DEPLOYING = "deploying"
    READY = "ready"
    UNREACHABLE = "unreachable"
    ERROR = "error"
    TERMINATED = "terminated"


class TeamInstance(Base):
    """A CloudSim this one (the master) runs for a team on a `cloudsim` constellation.

    Its credentials (an admin API token, the HTTPS certificate) are the constellation's
    encrypted secrets; `cert_fingerprint` is what the master pins when it calls.
    """

    __tablename__ = "team_instances"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(63))
    team_id: Mapped[int | None] = mapped_column(ForeignKey("teams.id"), index=True)
    constellation_id: Mapped[int] = mapped_column(
        ForeignKey("constellations.id", ondelete="CASCADE"), index=True
    )
    state: Mapped[InstanceState] = mapped_column(
        str_enum(InstanceState), default=InstanceState.DEPLOYING
    )
    url: Mapped[str | None] = mapped_column(String(255))
    cert_fingerprint: Mapped[str | None] = mapped_column(String(64))
    version: Mapped[str | None] = mapped_column(String(64))
    # the instance's last answer to a health check: database, queue, worker
    health: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    error: Mapped[str | None] = mapped_column(Text)  # why it is in error or unreachable
    checked_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    # when it last answered the master (a health check or a sync), unlike checked_at
    heard_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    last_sync_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    sync_error: Mapped[str | None] = mapped_column(Text)  # why it is behind, if it is
    # what the last sync changed (drift put back, or the master's news) and what it reported
    sync_report: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    # the constellation launched through it, as the master last saw it (see team_instances.launch)
    launch: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)

    team: Mapped[Team | None] = relationship()
    constellation: Mapped[Constellation] = relationship()

    def __repr__(self) -> str:
        return f"<TeamInstance {self.id} {self.name!r} team={self.team_id} {self.state}>"
