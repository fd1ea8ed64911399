"""Save a season's phases, make each phase's tasks for the teams that may enter, reveal scores."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from sqlalchemy import ColumnElement, and_, func, or_, select
from sqlalchemy.orm import selectinload

from cloudsim.audit.service import record
from cloudsim.auth.policy import Actor, require_role
from cloudsim.competition.schedule import (
    DEFAULT_DOWNLINK_BITS,
    DEFAULT_LATENCY_MS,
    DEFAULT_TIMEOUT_S,
    DEFAULT_UPLINK_BITS,
    TaskSpec,
    add_task,
    check_spec,
)
from cloudsim.errors import Conflict, InvalidInput, NotFound
from cloudsim.extensions import db
from cloudsim.models import Phase, Role, Run, RunState, Task, Team, utcnow

PHASE_NAME_MAX = 60
MAX_WORLDS = 100
MAX_LIMIT = 100_000
LIMITS = ("max_runs_per_task", "max_runs_per_day", "max_runs_total", "max_runs_at_once")


@dataclass(frozen=True)
class PhaseSpec:
    """A phase as an officer writes it; the window is already in UTC."""

    name: str
    window_start: object  # datetime, checked by check_phase through TaskSpec
    window_stop: object
    worlds: tuple[tuple[str, int], ...]
    time_zone: str = "UTC"
    position: int = 0
    timeout_s: int = DEFAULT_TIMEOUT_S
    latency_ms: int = DEFAULT_LATENCY_MS
    uplink_bits: int = DEFAULT_UPLINK_BITS
    downlink_bits: int = DEFAULT_DOWNLINK_BITS
    entry_after: str | None = None  # the earlier phase that qualifies teams; None: all teams
    entry_min_score: int | None = None
    limits: dict[str, int | None] = field(default_factory=dict)
    scores_hidden: bool = False
    counts_in_ranking: bool = True


def check_phase(spec: PhaseSpec) -> PhaseSpec:
    """Return the spec tidied, or raise InvalidInput naming the field that is wrong."""
    name = " ".join(spec.name.split())
    if not name or len(name) > PHASE_NAME_MAX or ":" in name:
        raise InvalidInput(f"name: 1-{PHASE_NAME_MAX} characters, no ':'")
    if not spec.worlds:
        raise InvalidInput("worlds: a phase needs at least one world and configuration")
    if len(spec.worlds) > MAX_WORLDS:
        raise InvalidInput(f"worlds: at most {MAX_WORLDS} world configurations")
    if len(set(spec.worlds)) != len(spec.worlds):
        raise InvalidInput("worlds: a world configuration is listed twice")
    for world, config in spec.worlds:
        try:
            check_spec(_task_spec(replace(spec, name=name), world, config, 0))
        except InvalidInput as exc:
            raise InvalidInput(f"{_field_of(str(exc))}: {exc}") from None
    for key in LIMITS:
        value = spec.limits.get(key)
        if value is not None and not 1 <= value <= MAX_LIMIT:
            raise InvalidInput(f"limits: {_limit_name(key)} must be 1-{MAX_LIMIT}, or left out")
    unknown = set(spec.limits) - set(LIMITS)
    if unknown:
        raise InvalidInput(f"limits: unknown {', '.join(sorted(unknown))}")
    if (spec.entry_after is None) != (spec.entry_min_score is None):
        raise InvalidInput("entry: give both the earlier phase and its minimum score")
    if spec.entry_min_score is not None and not 0 <= spec.entry_min_score <= MAX_LIMIT:
        raise InvalidInput(f"entry: min_score must be 0-{MAX_LIMIT}")
    if spec.entry_after is not None and spec.entry_after.strip() == name:
        raise InvalidInput("entry: a phase cannot qualify teams for itself")
    if not -10_000 <= spec.position <= 10_000:
        raise InvalidInput("position must be between -10000 and 10000")
    return replace(spec, name=name, time_zone=spec.time_zone.strip())


def _field_of(message: str) -> str:
    for word, key in (
        ("world", "worlds"),
        ("configuration", "worlds"),
        ("zone", "time_zone"),
        ("window", "stop"),
        ("timeout", "timeout_s"),
        ("latency", "latency_ms"),
        ("uplink", "uplink_bits"),
        ("downlink", "downlink_bits"),
    ):
        if word in message:
            return key
    return "phase"


def _limit_name(key: str) -> str:
    return key.removeprefix("max_runs_")


def _task_spec(spec: PhaseSpec | Phase, world: str, config: int, order: int) -> TaskSpec:
    return TaskSpec(
        name=f"{spec.name}: {world} #{config}",
        world=world,
        run_config=config,
        window_start=spec.window_start,  # type: ignore[arg-type]
        window_stop=spec.window_stop,  # type: ignore[arg-type]
        timeout_s=spec.timeout_s,
        latency_ms=spec.latency_ms,
        uplink_bits=spec.uplink_bits,
        downlink_bits=spec.downlink_bits,
        order=order,
        time_zone=spec.time_zone,
    )


def save_phase(actor: Actor, spec: PhaseSpec) -> Phase:
    """Create the phase, or change the one of that name (officers); its unrun tasks follow."""
    require_role(actor, Role.OFFICER, "change the season's phases")
    spec = check_phase(spec)
    entry = None
    if spec.entry_after is not None:
        entry = find_phase(actor, spec.entry_after)
    phase = db.session.scalar(select(Phase).where(Phase.name == spec.name))
    if phase is None:
        phase = Phase(name=spec.name)
        db.session.add(phase)
    if entry is not None and _leads_to(entry, phase):
        raise InvalidInput(f"entry: {entry.name} is entered through {phase.name} itself")
    phase.position = spec.position
    phase.window_start = spec.window_start  # type: ignore[assignment]
    phase.window_stop = spec.window_stop  # type: ignore[assignment]
    phase.time_zone = spec.time_zone
    phase.worlds = [[w, c] for w, c in spec.worlds]
    phase.timeout_s = spec.timeout_s
    phase.latency_ms = spec.latency_ms
    phase.uplink_bits = spec.uplink_bits
    phase.downlink_bits = spec.downlink_bits
    phase.entry_phase = entry
    phase.entry_min_score = spec.entry_min_score
    for key in LIMITS:
        setattr(phase, key, spec.limits.get(key))
    phase.scores_hidden = spec.scores_hidden
    phase.counts_in_ranking = spec.counts_in_ranking
    db.session.flush()
    _follow(phase)
    record("phase.save", actor, target_type="phase", target_id=phase.id, name=phase.name)
    return phase


def _leads_to(entry: Phase, phase: Phase) -> bool:
    seen: Phase | None = entry
    while seen is not None:
        if seen is phase:
            return True
        seen = seen.entry_phase
    return False


def _follow(phase: Phase) -> None:
    """Give the phase's tasks nobody has run yet its window and limits; drop dropped worlds."""
    wanted = {(w, c) for w, c in phase.worlds}
    for task in db.session.scalars(select(Task).where(Task.phase_id == phase.id)):
        if task.runs:
            continue  # a run was made under the old settings: the record keeps them
        if (task.world, task.run_config) not in wanted:
            db.session.delete(task)
            continue
        spec = _task_spec(phase, task.world, task.run_config, task.order)
        for name, value in spec.__dict__.items():
            setattr(task, name, value)
    db.session.flush()


def find_phase(actor: Actor, name: str) -> Phase:
    """Return the phase called name (the season's rules: every signed-in person may read them)."""
    phase = db.session.scalar(select(Phase).where(Phase.name == " ".join(name.split())))
    if phase is None:
        raise NotFound.of("phase", repr(name))
    return phase


def list_phases() -> list[Phase]:
    """Return the season's phases in order."""
    query = select(Phase).options(selectinload(Phase.entry_phase))
    return list(db.session.scalars(query.order_by(Phase.position, Phase.id)))


def phase_score(phase: Phase, team_id: int) -> int:
    """Return the team's points in the phase: its finished runs nobody invalidated."""
    total = db.session.scalar(
        select(func.coalesce(func.sum(Run.score), 0))
        .join(Task, Run.task_id == Task.id)
        .where(
            Task.phase_id == phase.id,
            Run.team_id == team_id,
            Run.state == RunState.FINISHED,
            Run.invalidated_at.is_(None),
        )
    )
    return int(total or 0)


def entrants(phase: Phase) -> list[Team]:
    """Return the teams that may enter the phase, raising Conflict while that is undecided."""
    teams = list(db.session.scalars(select(Team).order_by(Team.name)))
    entry = phase.entry_phase
    if entry is None:
        return teams
    if utcnow() < entry.window_stop:
        raise Conflict(
            f"entry to {phase.name} is decided when {entry.name} closes at "
            f"{entry.window_stop:%Y-%m-%d %H:%M} UTC; schedule it then"
        )
    floor = phase.entry_min_score or 0
    return [team for team in teams if phase_score(entry, team.id) >= floor]


def schedule_phase(actor: Actor, phase: Phase) -> list[Task]:
    """Make the phase's tasks for every team that may enter it (those made before are kept)."""
    require_role(actor, Role.OFFICER, "schedule a phase")
    teams = entrants(phase)
    have = {
        tuple(row)
        for row in db.session.execute(
            select(Task.team_id, Task.world, Task.run_config).where(Task.phase_id == phase.id)
        )
    }
    created = []
    for team in teams:
        for order, (world, config) in enumerate(phase.worlds, start=1):
            if (team.id, world, config) in have:
                continue
            task = add_task(actor, _task_spec(phase, world, config, order), team)
            task.phase_id = phase.id
            created.append(task)
    db.session.flush()
    record("phase.schedule", actor, target_type="phase", target_id=phase.id, created=len(created))
    return created


def reveal(actor: Actor, phase: Phase) -> Phase:
    """Show the phase's hidden scores to the teams from now on (officers; audited)."""
    require_role(actor, Role.OFFICER, "reveal scores")
    if not phase.scores_hidden:
        raise Conflict(f"the scores of {phase.name} are shown live; there is nothing to reveal")
    if phase.revealed_at is None:
        phase.revealed_at = utcnow()
        record("phase.reveal", actor, target_type="phase", target_id=phase.id)
    db.session.flush()
    return phase


def ranked_tasks(team_user: bool) -> ColumnElement[bool]:
    """Return the condition on Task (outer-joined with Phase) for runs the ranking counts:
    tasks of no phase, or of a phase that counts; a team user's board waits for a reveal."""
    counts: ColumnElement[bool] = Phase.counts_in_ranking.is_(True)
    if team_user:
        counts = and_(counts, or_(Phase.scores_hidden.is_(False), Phase.revealed_at.is_not(None)))
    return or_(Task.phase_id.is_(None), counts)
