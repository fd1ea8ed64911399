"""Schedule tasks for teams and find the ones a person may see; every rule checked here."""

from __future__ import annotations

from dataclasses import dataclass, replace
from datetime import UTC, datetime
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from sqlalchemy import Select, select
from sqlalchemy.orm import selectinload

from cloudsim.audit.service import record
from cloudsim.auth.policy import Actor, require_role, require_team_access
from cloudsim.errors import Conflict, InvalidInput, NotFound
from cloudsim.extensions import db
from cloudsim.models import Role, Task, Team, utcnow
from cloudsim.worlds.service import check_world

NAME_MAX = 120
MAX_TIMEOUT_S = 24 * 3600
MAX_LATENCY_MS = 2000
MAX_BITS = 10**15
DEFAULT_TIMEOUT_S = 1800  # the VRC's 30 minutes
DEFAULT_LATENCY_MS = 250  # each way, as in the VRC
DEFAULT_UPLINK_BITS = 29_491_200  # the VRC's largest uplink cap
DEFAULT_DOWNLINK_BITS = 943_718_400
# Windows stay far from datetime's limits, so that every zone can show them.
EARLIEST = datetime(2000, 1, 1, tzinfo=UTC)
LATEST = datetime(9000, 1, 1, tzinfo=UTC)
LOCAL_FORMATS = ("%Y-%m-%d %H:%M", "%Y-%m-%dT%H:%M", "%Y-%m-%d %H:%M:%S", "%Y-%m-%dT%H:%M:%S")


@dataclass(frozen=True)
class TaskSpec:
    """What an officer asks for; the window is already in UTC."""

    name: str
    world: str
    run_config: int
    window_start: datetime
    window_stop: datetime
    timeout_s: int = DEFAULT_TIMEOUT_S
    latency_ms: int = DEFAULT_LATENCY_MS
    uplink_bits: int = DEFAULT_UPLINK_BITS
    downlink_bits: int = DEFAULT_DOWNLINK_BITS
    order: int = 0
    time_zone: str = "UTC"


def zone(name: str) -> ZoneInfo:
    """Return the time zone called name (IANA, e.g. Europe/Berlin) or raise InvalidInput."""
    try:
        return ZoneInfo(name.strip())
    except (ZoneInfoNotFoundError, ValueError):
        raise InvalidInput(
            f"unknown time zone {name!r}; use an IANA name like Europe/Berlin"
        ) from None


def to_utc(value: str | datetime, zone_name: str) -> datetime:
    """Read a wall-clock time in the named zone (or an aware time) and return it in UTC."""
    if isinstance(value, str):
        text = value.strip()
        parsed = None
        for pattern in LOCAL_FORMATS:
            try:
                parsed = datetime.strptime(text, pattern)
                break
            except ValueError:
                continue
        if parsed is None:
            try:
                parsed = datetime.fromisoformat(text)
            except ValueError:
                raise InvalidInput(f"{value!r} is not a time like 2026-06-17 09:00") from None
        value = parsed
    if value.tzinfo is None:
        value = value.replace(tzinfo=zone(zone_name))
    span = f"times must fall in the years {EARLIEST.year}-{LATEST.year - 1}"
    try:
        utc = value.astimezone(UTC)
    except (OverflowError, ValueError):  # year 1 east of UTC, year 9999 west of it
        raise InvalidInput(span) from None
    if not EARLIEST <= utc < LATEST:
        raise InvalidInput(span)
    return utc


def in_zone(value: datetime, zone_name: str) -> datetime:
    """Return a stored UTC time as wall-clock time in the named zone."""
    return value.astimezone(zone(zone_name))


def check_spec(spec: TaskSpec) -> TaskSpec:
    """Return the spec with its name and zone tidied, or raise InvalidInput naming a problem."""
    name = " ".join(spec.name.split())
    if not name or len(name) > NAME_MAX:
        raise InvalidInput(f"task name must be 1-{NAME_MAX} characters")
    check_world(spec.world, spec.run_config)
    zone(spec.time_zone)
    if spec.window_start.tzinfo is None or spec.window_stop.tzinfo is None:
        raise InvalidInput("window times must carry a time zone")
    if spec.window_stop <= spec.window_start:
        raise InvalidInput("the window must end after it starts")
    if not 1 <= spec.timeout_s <= MAX_TIMEOUT_S:
        raise InvalidInput(f"timeout must be 1-{MAX_TIMEOUT_S} seconds")
    if not 0 <= spec.latency_ms <= MAX_LATENCY_MS:
        raise InvalidInput(f"latency must be 0-{MAX_LATENCY_MS} ms each way")
    for label, bits in (("uplink", spec.uplink_bits), ("downlink", spec.downlink_bits)):
        if not 0 <= bits <= MAX_BITS:
            raise InvalidInput(f"{label} cap must be 0-{MAX_BITS} bits")
    if not -10_000 <= spec.order <= 10_000:
        raise InvalidInput("order must be between -10000 and 10000")
    return replace(spec, name=name, time_zone=spec.time_zone.strip())


def _teams(team_ids: list[int] | None) -> list[Team]:
    if team_ids is None:
        teams = list(db.session.scalars(select(Team).order_by(Team.name)))
        if not teams:
            raise Conflict("there are no teams to schedule tasks for")
        return teams
    if not team_ids:
        raise InvalidInput("choose at least one team, or all teams")
    teams = []
    for team_id in dict.fromkeys(team_ids):
        team = db.session.get(Team, team_id)
        if team is None:
            raise NotFound.of("team", team_id)
        teams.append(team)
    return teams


def schedule(actor: Actor, spec: TaskSpec, team_ids: list[int] | None) -> list[Task]:
    """Create the task for each team (None: every team); officers and admins."""
    require_role(actor, Role.OFFICER, "schedule tasks")
    spec = check_spec(spec)
    tasks = [add_task(actor, spec, team) for team in _teams(team_ids)]
    return tasks


def add_task(actor: Actor, spec: TaskSpec, team: Team) -> Task:
    """Add one checked task for a team to the session."""
    task = Task(team_id=team.id, **spec.__dict__)
    db.session.add(task)
    db.session.flush()
    record(
        "task.schedule",
        actor,
        target_type="task",
        target_id=task.id,
        team_id=team.id,
        name=task.name,
        world=task.world,
        run_config=task.run_config,
        window=[task.window_start.isoformat(), task.window_stop.isoformat()],
    )
    return task


def delete_task(actor: Actor, task_id: int) -> None:
    """Remove a task nobody has run yet (officers and admins)."""
    require_role(actor, Role.OFFICER, "delete tasks")
    task = get_task(actor, task_id)
    if task.runs:
        raise Conflict(f"task {task.name!r} has runs; it stays for the record")
    record("task.delete", actor, target_type="task", target_id=task.id, team_id=task.team_id)
    db.session.delete(task)
    db.session.flush()


def get_task(actor: Actor, task_id: int) -> Task:
    """Return a task the actor may see: a team user sees their team's, once its window opened."""
    task = db.session.get(Task, task_id)
    if task is None:
        raise NotFound.of("task", task_id)
    require_team_access(actor, task.team_id, "task", task_id)
    if not _sees_everything(actor) and task.window_start > utcnow():
        raise NotFound.of("task", task_id)
    return task


def visible_tasks(actor: Actor) -> Select[Task]:
    """Return a query for the tasks the actor may see, in schedule order."""
    query = (
        select(Task)
        .options(selectinload(Task.team))
        .order_by(Task.window_start, Task.order, Task.id)
    )
    if not _sees_everything(actor):
        assert actor is not None
        query = query.where(
            Task.team_id == actor.team_id,
            Task.team_id.is_not(None),
            Task.window_start <= utcnow(),
        )
    return query


def open_tasks(actor: Actor, team_id: int | None = None) -> list[Task]:
    """Return the tasks whose window is open now (a team user: their team's only)."""
    now = utcnow()
    query = visible_tasks(actor).where(Task.window_start <= now, Task.window_stop > now)
    if team_id is not None:
        query = query.where(Task.team_id == team_id)
    return list(db.session.scalars(query))


def _sees_everything(actor: Actor) -> bool:
    return actor is None or actor.has_role(Role.OFFICER)
