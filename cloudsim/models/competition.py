"""The competition: scheduled tasks, the runs teams make of them, their logs and score events."""

from __future__ import annotations

import enum
from datetime import datetime
from typing import TYPE_CHECKING, Any

from sqlalchemy import JSON, BigInteger, ForeignKey, Index, String, Text, UniqueConstraint, text
from sqlalchemy.orm import Mapped, mapped_column, relationship

from cloudsim.models.base import Base, UTCDateTime, str_enum, utcnow

if TYPE_CHECKING:
    from cloudsim.models.machines import Constellation
    from cloudsim.models.people import Team, User
    from cloudsim.models.portal import PortalUpload
    from cloudsim.models.seasons import Phase
    from cloudsim.models.team_instances import TeamInstance


class Task(Base):
    """A world and run configuration a team may run inside a time window, with network limits."""

    __tablename__ = "tasks"

    id: Mapped[int] = mapped_column(primary_key=True)
    team_id: Mapped[int] = mapped_column(ForeignKey("teams.id", ondelete="CASCADE"), index=True)
    name: Mapped[str] = mapped_column(String(120))
    world: Mapped[str] = mapped_column(String(64))
    run_config: Mapped[int] = mapped_column(default=1)
    window_start: Mapped[datetime] = mapped_column(UTCDateTime)
    window_stop: Mapped[datetime] = mapped_column(UTCDateTime)
    timeout_s: Mapped[int] = mapped_column(default=1800)
    latency_ms: Mapped[int] = mapped_column(default=250)
    uplink_bits: Mapped[int] = mapped_column(BigInteger)
    downlink_bits: Mapped[int] = mapped_column(BigInteger)
    order: Mapped[int] = mapped_column(default=0)
    # The zone the officer entered the window in: pages and exports show it that way again.
    time_zone: Mapped[str] = mapped_column(String(64), default="UTC")
    # on a team instance: the master's task this one copies ("m<id>"); None: made here
    master_key: Mapped[str | None] = mapped_column(String(32), unique=True)
    # the season's phase this task was made from (cloudsim.seasons); None: scheduled by hand.
    # No ON DELETE: a phase with tasks cannot be deleted (SQLite adds the column in place).
    phase_id: Mapped[int | None] = mapped_column(ForeignKey("phases.id"), index=True)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)

    team: Mapped[Team] = relationship()
    phase: Mapped[Phase | None] = relationship()
    runs: Mapped[list[Run]] = relationship(back_populates="task")

    def __repr__(self) -> str:
        return f"<Task {self.id} {self.name!r} team={self.team_id} {self.world}#{self.run_config}>"

    def is_open(self, at: datetime) -> bool:
        """Return True when `at` lies inside the task's window."""
        return self.window_start <= at < self.window_stop


class RunState(enum.StrEnum):
    """Life cycle of a run."""

    STARTING = "starting"
    RUNNING = "running"
    STOPPING = "stopping"
    FINISHED = "finished"
    ERROR = "error"
    # its end could not be established (its stop kept failing): an officer settles it
    NEEDS_REVIEW = "needs_review"


class Verification(enum.StrEnum):
    """What re-simulating a finished run from its own logs found (not its life cycle)."""

    VERIFYING = "verifying"  # queued or under way
    VERIFIED = "verified"  # the replay reproduced the score log and the final state
    HELD = "held"  # held for review: something did not match (the reason says what)
    ACCEPTED = "accepted"  # held, then accepted by an officer (audited)


# The one run of a task that is live or counts (finished, not invalidated).
LIVE_OR_COUNTED = (
    "state IN ('starting', 'running', 'stopping') "
    "OR (state = 'finished' AND invalidated_at IS NULL)"
)


class Run(Base):
    """One attempt by a team at a task, on one of its constellations.

    On a master, a run a team instance uploaded (cloudsim.portal) is a row like any other,
    marked with the instance and the instance's own id for it (one row per pair). A task has
    at most one run that is live or counts (finished, not invalidated): the database holds that
    too, so two uploads, or two starts on two constellations, at the same instant cannot both
    be stored.
    """

    __tablename__ = "runs"
    __table_args__ = (
        UniqueConstraint("instance_id", "remote_run_id"),
        Index(
            "uq_runs_task_live_or_counted",
            "task_id",
            unique=True,
            sqlite_where=text(LIVE_OR_COUNTED),
            postgresql_where=text(LIVE_OR_COUNTED),
        ),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    task_id: Mapped[int] = mapped_column(ForeignKey("tasks.id", ondelete="CASCADE"), index=True)
    team_id: Mapped[int] = mapped_column(ForeignKey("teams.id", ondelete="CASCADE"), index=True)
    constellation_id: Mapped[int | None] = mapped_column(
        ForeignKey("constellations.id", ondelete="SET NULL"), index=True
    )
    started_by_id: Mapped[int | None] = mapped_column(ForeignKey("users.id", ondelete="SET NULL"))
    state: Mapped[RunState] = mapped_column(str_enum(RunState), default=RunState.STARTING)
    # Set while the run is live and cleared when it ends: the unique index lets the database
    # refuse a second live run on one constellation even when two starts race.
    active_constellation_id: Mapped[int | None] = mapped_column(unique=True)
    # Why the run is being stopped (the user, the window, the time limit), before it ends.
    stop_reason: Mapped[str | None] = mapped_column(String(32))
    end_reason: Mapped[str | None] = mapped_column(String(32))
    error: Mapped[str | None] = mapped_column(Text)
    error_code: Mapped[str | None] = mapped_column(String(32))  # cloudsim.error_codes
    review_since: Mapped[datetime | None] = mapped_column(UTCDateTime)  # went to needs_review
    score: Mapped[int] = mapped_column(default=0)
    falls: Mapped[int] = mapped_column(default=0)
    sim_seconds: Mapped[float] = mapped_column(default=0.0)
    uplink_bits_used: Mapped[int] = mapped_column(BigInteger, default=0)
    downlink_bits_used: Mapped[int] = mapped_column(BigInteger, default=0)
    # when a direction's cap was spent (its traffic dropped from then on), None while it lasts
    uplink_spent_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    downlink_spent_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    started_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    running_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    finished_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    # uploaded from a team instance (on the master): which one, its id there, what it declared
    instance_id: Mapped[int | None] = mapped_column(
        ForeignKey("team_instances.id", ondelete="SET NULL"), index=True
    )
    remote_run_id: Mapped[int | None] = mapped_column()
    uploaded_at: Mapped[datetime | None] = mapped_column(UTCDateTime)  # its record arrived
    # the logs the instance declared: [{"filename", "kind", "size", "sha256"}]
    upload_manifest: Mapped[list[dict[str, Any]] | None] = mapped_column(JSON)
    logs_complete_at: Mapped[datetime | None] = mapped_column(UTCDateTime)  # all logs checked
    # an officer's word on the run (audited); an invalidated run does not count in the ranking
    officer_note: Mapped[str | None] = mapped_column(Text)
    invalidated_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    invalid_reason: Mapped[str | None] = mapped_column(Text)
    # re-simulation of the finished run from its logs (cloudsim.verification); None: not yet
    verification: Mapped[Verification | None] = mapped_column(str_enum(Verification), index=True)
    verification_reason: Mapped[str | None] = mapped_column(Text)  # why held, or accepted
    verified_at: Mapped[datetime | None] = mapped_column(UTCDateTime)  # when it was decided

    task: Mapped[Task] = relationship(back_populates="runs")
    team: Mapped[Team] = relationship()
    constellation: Mapped[Constellation | None] = relationship()
    started_by: Mapped[User | None] = relationship()
    instance: Mapped[TeamInstance | None] = relationship()
    # on a team instance: its upload to the master's portal (the outbox row; cloudsim.portal)
    upload: Mapped[PortalUpload | None] = relationship(viewonly=True)
    artifacts: Mapped[list[Artifact]] = relationship(
        back_populates="run", cascade="all, delete-orphan"
    )
    score_events: Mapped[list[ScoreEvent]] = relationship(
        back_populates="run", cascade="all, delete-orphan", order_by="ScoreEvent.sim_time"
    )

    def __repr__(self) -> str:
        return f"<Run {self.id} task={self.task_id} team={self.team_id} {self.state} {self.score}>"


class Artifact(Base):
    """A log file of a run, stored outside the database and identified by its checksum."""

    __tablename__ = "artifacts"
    __table_args__ = (UniqueConstraint("run_id", "filename"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), index=True)
    kind: Mapped[str] = mapped_column(String(32))
    filename: Mapped[str] = mapped_column(String(255))
    location: Mapped[str] = mapped_column(String(1024))
    size: Mapped[int] = mapped_column(BigInteger, default=0)
    sha256: Mapped[str] = mapped_column(String(64))
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)

    run: Mapped[Run] = relationship(back_populates="artifacts")

    def __repr__(self) -> str:
        return f"<Artifact {self.id} run={self.run_id} {self.kind} {self.size}B>"


class ScoreEvent(Base):
    """A checkpoint reached (or a fall) during a run, with simulated and wall time."""

    __tablename__ = "score_events"

    id: Mapped[int] = mapped_column(primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), index=True)
    kind: Mapped[str] = mapped_column(String(16), default="checkpoint")
    checkpoint: Mapped[int | None] = mapped_column()
    points: Mapped[int] = mapped_column(default=0)
    sim_time: Mapped[float] = mapped_column()
    wall_time: Mapped[datetime] = mapped_column(UTCDateTime)
    description: Mapped[str] = mapped_column(String(255), default="")

    run: Mapped[Run] = relationship(back_populates="score_events")

    def __repr__(self) -> str:
        return f"<ScoreEvent run={self.run_id} {self.kind} {self.checkpoint} t={self.sim_time}>"
