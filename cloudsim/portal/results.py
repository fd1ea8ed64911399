"""The season's results as the portal shows and exports them: one row per run, team-scoped.

Runs finished on the master and runs uploaded from team instances are the same `Run` rows;
this module is the one place that reads them for the portal's pages, figures and exports.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import Select, select

from cloudsim.auth.policy import Actor
from cloudsim.extensions import db
from cloudsim.models import Role, Run, RunState, Task, Team, TeamInstance, Verification
from cloudsim.models.team_instances import InstanceState
from cloudsim.verification.service import label

MASTER = "master"  # the source of a run finished on this CloudSim itself
GONE = "a removed team instance"  # uploaded by an instance whose row was deleted since


@dataclass(frozen=True)
class ResultRow:
    """One run with its task's terms, as exported and plotted."""

    run_id: int
    team_id: int
    team: str
    task: str
    world: str
    run_config: int
    state: str
    started_at: datetime
    finished_at: datetime | None
    end_reason: str | None
    score: int
    falls: int
    sim_seconds: float
    timeout_s: int
    uplink_bits_used: int
    uplink_cap_bits: int
    downlink_bits_used: int
    downlink_cap_bits: int
    source: str
    invalidated: bool
    invalid_reason: str | None
    officer_note: str | None
    verification: str  # as shown: unverified, verifying, verified, held for review, accepted ...
    verification_reason: str | None

    @property
    def scoring(self) -> bool:
        """Return True when the run counts: finished, not invalidated, not held for review."""
        return (
            self.state == RunState.FINISHED.value
            and not self.invalidated
            and self.verification != label(Verification.HELD)
        )

    @property
    def uplink_bits_banked(self) -> int:
        """Return the uplink bits the run left unused (what the VRC called banked)."""
        return max(0, self.uplink_cap_bits - self.uplink_bits_used)

    def exported(self) -> dict[str, Any]:
        """Return the row as plain JSON values (times in ISO 8601 UTC)."""
        # Not dataclasses.asdict: it deep-copies each value (26 ms for 450 rows, not 1 ms).
        values = {name: getattr(self, name) for name in FIELDS}
        for key in ("started_at", "finished_at"):
            values[key] = values[key].isoformat() if values[key] else None
        return values


FIELDS = tuple(ResultRow.__dataclass_fields__)


def _columns() -> Select[Any]:
    """Return the query of every run's row, its columns named as ResultRow's fields."""
    return (
        select(  # type: ignore[return-value]
            Run.id.label("run_id"),
            Run.team_id,
            Team.name.label("team"),
            Task.name.label("task"),
            Task.world,
            Task.run_config,
            Run.state,
            Run.started_at,
            Run.finished_at,
            Run.end_reason,
            Run.score,
            Run.falls,
            Run.sim_seconds,
            Task.timeout_s,
            Run.uplink_bits_used,
            Task.uplink_bits.label("uplink_cap_bits"),
            Run.downlink_bits_used,
            Task.downlink_bits.label("downlink_cap_bits"),
            TeamInstance.name.label("source"),
            Run.remote_run_id,
            Run.invalidated_at,
            Run.invalid_reason,
            Run.officer_note,
            Run.verification,
            Run.verification_reason,
        )
        .join(Task, Run.task_id == Task.id)
        .join(Team, Run.team_id == Team.id)
        .outerjoin(TeamInstance, Run.instance_id == TeamInstance.id)
    )


def _visible(query: Select[Any], actor: Actor, team_id: int | None = None) -> Select[Any]:
    """Keep the runs (joined with their team) the actor may see, one team's if given, by team
    then start time."""
    query = query.order_by(Team.name, Run.started_at, Run.id)
    if not actor.has_role(Role.OFFICER):
        query = query.where(Run.team_id == actor.team_id, Run.team_id.is_not(None))
    if team_id is not None:
        query = query.where(Run.team_id == team_id)
    return query


def results(actor: Actor, team_id: int | None = None) -> list[ResultRow]:
    """Return the runs the actor may see (one team's if given), by team then start time."""
    # Columns, not rows: a season's 450 runs are read without building an ORM object each.
    rows = []
    for row in db.session.execute(_visible(_columns(), actor, team_id)):
        values = row._asdict()
        values["state"] = values["state"].value
        uploaded = values.pop("remote_run_id") is not None
        values["source"] = values["source"] or (GONE if uploaded else MASTER)
        values["invalidated"] = values.pop("invalidated_at") is not None
        values["verification"] = label(values["verification"])
        rows.append(ResultRow(**values))
    return rows


def scoring_run_ids(actor: Actor) -> Select[Any]:
    """Return the query of the ids of the runs that count (`ResultRow.scoring`: finished, not
    invalidated, not held) the actor may see, in `results`' order (for paging them)."""
    query = select(Run.id).join(Team, Run.team_id == Team.id)
    query = query.where(
        Run.state == RunState.FINISHED,
        Run.invalidated_at.is_(None),
        Run.verification.is_distinct_from(Verification.HELD),
    )
    return _visible(query, actor)


def team_cloudsims(team_ids: list[int] | None = None) -> dict[int, TeamInstance]:
    """Return per team its live team instance (the newest not terminated), if it has one."""
    query = select(TeamInstance).where(
        TeamInstance.team_id.is_not(None), TeamInstance.state != InstanceState.TERMINATED
    )
    if team_ids is not None:
        query = query.where(TeamInstance.team_id.in_(team_ids))
    found: dict[int, TeamInstance] = {}
    for instance in db.session.scalars(query.order_by(TeamInstance.id)):
        assert instance.team_id is not None
        found[instance.team_id] = instance  # the newest wins
    return found
