"""The phase's limits on a team's runs, checked by the server at every start."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

from sqlalchemy import select

from cloudsim.competition.schedule import in_zone
from cloudsim.errors import Forbidden
from cloudsim.extensions import db
from cloudsim.models import Phase, Run, RunState, Task, Team

LIVE = (RunState.STARTING, RunState.RUNNING, RunState.STOPPING)


class RuleRefused(Forbidden):
    """A phase's rule refuses a start: which rule, and when the team may try again."""

    def __init__(self, rule: str, message: str, retry_at: datetime | None) -> None:
        when = (
            f"try again after {retry_at:%Y-%m-%d %H:%M} UTC"
            if retry_at is not None
            else "no later start is allowed in this phase"
        )
        super().__init__(f"refused by the rule {rule}: {message}; {when}")
        self.rule = rule
        self.retry_at = retry_at


def check_run_limits(task: Task, now: datetime) -> None:
    """Raise RuleRefused when starting a run of the task now breaks a limit of its phase.

    A "task" here is the VRC's: a world, over all its run configurations. A run that ended
    in error counts against no limit: the team did not get its attempt.
    """
    phase = task.phase
    if phase is None:
        return
    # Two starts of one team at once would both count the runs before either is stored: on
    # PostgreSQL the team's row lock makes the second wait and count again (SQLite ignores it).
    db.session.execute(select(Team.id).where(Team.id == task.team_id).with_for_update())
    rows = db.session.execute(
        select(Task.world, Run.state, Run.started_at)
        .join(Task, Run.task_id == Task.id)
        .where(Task.phase_id == phase.id, Run.team_id == task.team_id)
    ).all()
    attempts = [row for row in rows if row.state != RunState.ERROR]
    if phase.max_runs_at_once is not None:
        live = sum(1 for row in attempts if row.state in LIVE)
        if live >= phase.max_runs_at_once:
            raise RuleRefused(
                "at_once",
                f"{phase.name} allows {phase.max_runs_at_once} run(s) at once and "
                f"{live} of yours are live",
                _soonest_end(phase, task, now),
            )
    if phase.max_runs_per_task is not None:
        done = sum(1 for row in attempts if row.world == task.world)
        if done >= phase.max_runs_per_task:
            raise RuleRefused(
                "per_task",
                f"{phase.name} allows {phase.max_runs_per_task} run(s) of each VRC task "
                f"(world) and you made {done} of {task.world}",
                None,
            )
    if phase.max_runs_total is not None and len(attempts) >= phase.max_runs_total:
        raise RuleRefused(
            "total", f"{phase.name} allows {phase.max_runs_total} run(s) in all", None
        )
    if phase.max_runs_per_day is not None:
        day_start, day_stop = _day(phase, now)
        today = sum(1 for row in attempts if day_start <= row.started_at < day_stop)
        if today >= phase.max_runs_per_day:
            retry = day_stop if day_stop < phase.window_stop else None
            raise RuleRefused(
                "per_day",
                f"{phase.name} allows {phase.max_runs_per_day} run(s) a day "
                f"(days in {phase.time_zone}) and you made {today} today",
                retry,
            )


def _soonest_end(phase: Phase, task: Task, now: datetime) -> datetime | None:
    """Return when the team's first live run ends at the latest (its time limit)."""
    ends = [
        started + timedelta(seconds=timeout)
        for started, timeout in db.session.execute(
            select(Run.started_at, Task.timeout_s)
            .join(Task, Run.task_id == Task.id)
            .where(Task.phase_id == phase.id, Run.team_id == task.team_id, Run.state.in_(LIVE))
        )
    ]
    soonest = min(ends, default=None)
    return max(soonest, now) if soonest is not None else None


def _day(phase: Phase, now: datetime) -> tuple[datetime, datetime]:
    """Return the UTC bounds of today in the phase's time zone."""
    local = in_zone(now, phase.time_zone)
    midnight = local.replace(hour=0, minute=0, second=0, microsecond=0)
    tomorrow = (midnight + timedelta(days=1)).replace(tzinfo=None)
    zone = midnight.tzinfo
    # midnight to midnight on the wall clock: 23 or 25 hours on the days the clocks change
    return midnight.astimezone(UTC), tomorrow.replace(tzinfo=zone).astimezone(UTC)
