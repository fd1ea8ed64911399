"""Constellations (sets of machines provisioned together) and their machines."""

from __future__ import annotations

import enum
from datetime import datetime
from typing import TYPE_CHECKING, Any

from sqlalchemy import JSON, ForeignKey, Index, String, Text, UniqueConstraint, text
from sqlalchemy.orm import Mapped, mapped_column, relationship

from cloudsim.models.base import Base, UTCDateTime, str_enum, utcnow

if TYPE_CHECKING:
    from cloudsim.models.people import Team, User


class ConstellationState(enum.StrEnum):
    """Life cycle of a constellation."""

    PENDING = "pending"
    LAUNCHING = "launching"
    READY = "ready"
    ERROR = "error"
    TERMINATING = "terminating"
    TERMINATED = "terminated"
    # a terminate left a machine not cleaned (the error says which and why); retry it
    TERMINATE_INCOMPLETE = "terminate_incomplete"


# The states of a constellation on its way out, or out: no job starts work on its machines.
GONE = (
    ConstellationState.TERMINATING,
    ConstellationState.TERMINATED,
    ConstellationState.TERMINATE_INCOMPLETE,
)


class MachineState(enum.StrEnum):
    """Life cycle of one machine."""

    PENDING = "pending"
    CREATING = "creating"
    RUNNING = "running"
    READY = "ready"
    ERROR = "error"
    TERMINATING = "terminating"
    TERMINATED = "terminated"


LIVE_NAME = "state != 'terminated'"


class Constellation(Base):
    """A named set of machines of one kind, on one provider, usually for one team.

    A name belongs to one live constellation at a time; terminated ones keep theirs, as
    history, and the name can be launched again.
    """

    __tablename__ = "constellations"
    __table_args__ = (
        Index(
            "uq_constellations_live_name",
            "name",
            unique=True,
            sqlite_where=text(LIVE_NAME),
            postgresql_where=text(LIVE_NAME),
        ),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(63))
    kind: Mapped[str] = mapped_column(String(32))
    # The kind's definition as it was at launch (its YAML data, validated): every job of this
    # constellation works from it, whatever happens to the kind's file later.
    definition: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    provider: Mapped[str] = mapped_column(String(32))
    team_id: Mapped[int | None] = mapped_column(ForeignKey("teams.id"), index=True)
    state: Mapped[ConstellationState] = mapped_column(
        str_enum(ConstellationState, length=24), default=ConstellationState.PENDING
    )
    error: Mapped[str | None] = mapped_column(Text)
    error_code: Mapped[str | None] = mapped_column(String(32))  # cloudsim.error_codes
    # Provider-side identifiers (network id, security groups, ...) needed to clean up.
    resources: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    # May the team's account on the field computers use sudo? Officers decide; off by default.
    team_sudo: Mapped[bool] = mapped_column(default=False, server_default="0")
    created_by_id: Mapped[int | None] = mapped_column(ForeignKey("users.id", ondelete="SET NULL"))
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow, onupdate=utcnow)

    team: Mapped[Team | None] = relationship(back_populates="constellations")
    created_by: Mapped[User | None] = relationship()
    machines: Mapped[list[Machine]] = relationship(
        back_populates="constellation", cascade="all, delete-orphan", order_by="Machine.id"
    )

    def __repr__(self) -> str:
        return f"<Constellation {self.id} {self.name!r} {self.kind}/{self.provider} {self.state}>"


class Machine(Base):
    """One machine of a constellation, with the role it plays in it."""

    __tablename__ = "machines"
    __table_args__ = (UniqueConstraint("constellation_id", "name"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    constellation_id: Mapped[int] = mapped_column(
        ForeignKey("constellations.id", ondelete="CASCADE"), index=True
    )
    name: Mapped[str] = mapped_column(String(63))
    role: Mapped[str] = mapped_column(String(32))
    size: Mapped[str] = mapped_column(String(64), default="")
    state: Mapped[MachineState] = mapped_column(
        str_enum(MachineState), default=MachineState.PENDING
    )
    provider_node_id: Mapped[str | None] = mapped_column(String(128), index=True)
    private_ip: Mapped[str | None] = mapped_column(String(45))
    public_ip: Mapped[str | None] = mapped_column(String(45))
    host_key: Mapped[str | None] = mapped_column(Text)
    # how the controller reaches it (provisioners.remote.ssh.Route), recorded at creation
    ssh_route: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    verification: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    error: Mapped[str | None] = mapped_column(Text)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow, onupdate=utcnow)

    constellation: Mapped[Constellation] = relationship(back_populates="machines")

    def __repr__(self) -> str:
        return f"<Machine {self.id} {self.name!r} role={self.role} {self.state}>"
