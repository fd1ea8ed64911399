"""A season's phases: which worlds, when, who may enter, how often, and how scores show."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import JSON, BigInteger, ForeignKey, String
from sqlalchemy.orm import Mapped, mapped_column, relationship

from cloudsim.models.base import Base, UTCDateTime, utcnow


class Phase(Base):
    """One phase of the season (practice, qualification, competition), its rules as data.

    The tasks of a phase are made from it for every team that may enter; a limit left None
    does not apply.
    """

    __tablename__ = "phases"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(60), unique=True)
    position: Mapped[int] = mapped_column(default=0)  # order of the phases in the season
    window_start: Mapped[datetime] = mapped_column(UTCDateTime)
    window_stop: Mapped[datetime] = mapped_column(UTCDateTime)
    time_zone: Mapped[str] = mapped_column(String(64), default="UTC")
    # [[world, run configuration], ...]: one task per pair for each team that may enter
    worlds: Mapped[list[Any]] = mapped_column(JSON)
    timeout_s: Mapped[int] = mapped_column(default=1800)
    latency_ms: Mapped[int] = mapped_column(default=250)
    uplink_bits: Mapped[int] = mapped_column(BigInteger)
    downlink_bits: Mapped[int] = mapped_column(BigInteger)
    # who may enter: every team, or (entry_phase set) those whose counted runs of that earlier
    # phase scored at least entry_min_score in total
    entry_phase_id: Mapped[int | None] = mapped_column(ForeignKey("phases.id"))
    entry_min_score: Mapped[int | None] = mapped_column()
    max_runs_per_task: Mapped[int | None] = mapped_column()
    max_runs_per_day: Mapped[int | None] = mapped_column()  # a day in the phase's time zone
    max_runs_total: Mapped[int | None] = mapped_column()
    max_runs_at_once: Mapped[int | None] = mapped_column()
    # hidden: teams see their runs' scores (and the phase on the leaderboard) once revealed
    scores_hidden: Mapped[bool] = mapped_column(default=False)
    revealed_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    counts_in_ranking: Mapped[bool] = mapped_column(default=True)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)

    entry_phase: Mapped[Phase | None] = relationship(remote_side=[id])

    def __repr__(self) -> str:
        return f"<Phase {self.id} {self.name!r}>"

    def scores_shown(self) -> bool:
        """Return True when team users may see the phase's scores."""
        return not self.scores_hidden or self.revealed_at is not None
