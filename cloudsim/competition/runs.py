"""Start, stop and look at runs, and rank the teams; every rule checked here for every caller."""

from __future__ import annotations

from collections import defaultdict

from flask import Response, current_app
from sqlalchemy import Select, func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import selectinload

from cloudsim.audit.service import record
from cloudsim.auth.policy import Actor, require_team_access
from cloudsim.competition import lifecycle
from cloudsim.competition.artifacts import LogStore
from cloudsim.competition.scoring import RunResult, Standing, rank
from cloudsim.errors import Conflict, Forbidden, NotFound
from cloudsim.extensions import db
from cloudsim.models import (
    Artifact,
    Constellation,
    ConstellationState,
    Phase,
    Role,
    Run,
    RunState,
    Task,
    Team,
    utcnow,
)
from cloudsim.seasons.rules import check_run_limits
from cloudsim.seasons.service import ranked_tasks
from cloudsim.verification import service as verification
from cloudsim.web.downloads import attachment

LIVE = (RunState.STARTING, RunState.RUNNING, RunState.STOPPING)
RUNNABLE_KINDS = ("vrc", "simple")
NOT_OPEN = "no task with that id is open for your team now"


def start_run(actor: Actor, task_id: int, constellation_id: int | None = None) -> Run:
    """Start a run of an open task on the team's ready constellation (the team, or officers)."""
    task = db.session.get(Task, task_id)
    is_team_user = actor is not None and not actor.has_role(Role.OFFICER)
    if task is None or (is_team_user and actor is not None and actor.team_id != task.team_id):
        if is_team_user:
            raise Forbidden(NOT_OPEN)
        raise NotFound.of("task", task_id)
    now = utcnow()
    if now < task.window_start:
        raise Forbidden(NOT_OPEN if is_team_user else f"the window of {task.name} is not open")
    if now >= task.window_stop:
        raise Forbidden(
            f"the window of {task.name} closed at {task.window_stop:%Y-%m-%d %H:%M} UTC"
        )
    _refuse_if_run(task)
    check_run_limits(task, now)
    constellation = _constellation_for(task, constellation_id)
    run = lifecycle.new_run(
        task_id=task.id,
        team_id=task.team_id,
        constellation_id=constellation.id,
        active_constellation_id=constellation.id,
        started_by_id=actor.id if actor else None,
    )
    db.session.add(run)
    try:
        db.session.flush()
    except IntegrityError:  # another start of this task, or on this constellation, at once
        db.session.rollback()
        _refuse_if_run(task)
        raise Conflict(f"{constellation.name} is busy with another run") from None
    record(
        "run.start",
        actor,
        target_type="run",
        target_id=run.id,
        team_id=task.team_id,
        task=task.name,
        constellation=constellation.name,
    )
    lifecycle.start(actor, run)
    return run


def task_run(task_id: int) -> int | None:
    """Return the id of the task's live or finished run, if it has one."""
    held = (*LIVE, RunState.FINISHED, RunState.NEEDS_REVIEW)  # a run in review may yet count
    return db.session.scalar(select(Run.id).where(Run.task_id == task_id, Run.state.in_(held)))


def _refuse_if_run(task: Task) -> None:
    done = task_run(task.id)
    if done is not None:
        raise Conflict(f"{task.name} has been run already (run {done})")


def _constellation_for(task: Task, constellation_id: int | None) -> Constellation:
    query = select(Constellation).where(
        Constellation.team_id == task.team_id, Constellation.kind.in_(RUNNABLE_KINDS)
    )
    if constellation_id is not None:
        query = query.where(Constellation.id == constellation_id)
    candidates = list(db.session.scalars(query.order_by(Constellation.id)))
    if not candidates:
        raise Conflict("the team has no constellation to run on; ask an admin to launch one")
    ready = [c for c in candidates if c.state == ConstellationState.READY]
    if not ready:
        states = ", ".join(f"{c.name} is {c.state.value}" for c in candidates)
        raise Conflict(f"no ready constellation: {states}")
    busy = set(
        db.session.scalars(
            select(Run.active_constellation_id).where(
                Run.active_constellation_id.in_([c.id for c in ready])
            )
        )
    )
    free = [c for c in ready if c.id not in busy]
    if not free:
        raise Conflict(f"{ready[0].name} is busy with another run; one run at a time")
    return free[0]


def stop_run(actor: Actor, run_id: int) -> Run:
    """Ask a live run to stop (its team, or officers); safe to repeat."""
    run = get_run(actor, run_id)
    if run.state not in LIVE:
        raise Conflict(f"run {run.id} is {run.state.value}")
    if run.stop_reason is None:
        record("run.stop", actor, target_type="run", target_id=run.id, team_id=run.team_id)
    lifecycle.request_stop(run, "stopped")
    return run


def settle_review(actor: Actor, run_id: int, accept: bool, note: str) -> Run:
    """Settle a run in review (officers): accept the end its logs show, or mark it failed."""
    run = get_run(actor, run_id)
    if actor is None or not actor.has_role(Role.OFFICER):
        raise Forbidden("only officers settle a run in review")
    if run.state != RunState.NEEDS_REVIEW:
        raise Conflict(f"run {run.id} is {run.state.value}, not in review")
    note = note.strip()
    if not note:
        raise Conflict("say why (what was checked) when settling a run")
    end_reason = run.end_reason or run.stop_reason or "reviewed"
    record(
        "run.review",
        actor,
        target_type="run",
        target_id=run.id,
        team_id=run.team_id,
        decision="accept" if accept else "fail",
        note=note[:2000],
    )
    run.officer_note = note[:2000]  # before settling: the notice it sends quotes it
    lifecycle.settled(run, accept, end_reason)
    db.session.flush()
    return run


def get_run(actor: Actor, run_id: int) -> Run:
    """Return a run the actor may see."""
    run = db.session.get(Run, run_id)
    if run is None:
        raise NotFound.of("run", run_id)
    require_team_access(actor, run.team_id, "run", run_id)
    return run


def get_log(actor: Actor, run_id: int, artifact_id: int) -> Artifact:
    """Return a stored log of a run the actor may see."""
    run = get_run(actor, run_id)
    artifact = db.session.get(Artifact, artifact_id)
    if artifact is None or artifact.run_id != run.id:
        raise NotFound.of(f"log {artifact_id} of run", run_id)
    return artifact


def log_download(actor: Actor, run_id: int, artifact_id: int) -> Response:
    """Return a stored log of a run the actor may see as a streamed download (page and API)."""
    artifact = get_log(actor, run_id, artifact_id)
    store = LogStore(current_app.config["CLOUDSIM"])
    return attachment(
        store.stream(artifact.location),
        f"run-{run_id}-{artifact.filename}",
        "application/octet-stream",
        headers={"Content-Length": str(artifact.size), "X-Checksum-SHA256": artifact.sha256},
    )


def visible_runs(actor: Actor) -> Select[Run]:
    """Return a query for the runs the actor may see, newest first."""
    query = (
        select(Run)
        .options(selectinload(Run.task), selectinload(Run.team))
        .order_by(Run.started_at.desc(), Run.id.desc())
    )
    if actor is not None and not actor.has_role(Role.OFFICER):
        query = query.where(Run.team_id == actor.team_id, Run.team_id.is_not(None))
    return query


def live_run(team_id: int) -> Run | None:
    """Return the team's live run, if any."""
    return db.session.scalar(
        select(Run).where(Run.team_id == team_id, Run.state.in_(LIVE)).order_by(Run.id.desc())
    )


def leaderboard(actor: Actor) -> list[Standing]:
    """Return the ranking of every team over their finished runs (not those an officer
    invalidated nor those held for review; unverified ones as CLOUDSIM_RANK_UNVERIFIED says;
    not those of a phase that does not count, nor, for teams, of one whose scores are still
    hidden), as much as the actor may see."""
    config = current_app.config["CLOUDSIM"]
    policy = config.leaderboard_for_users
    team_user = actor is not None and not actor.has_role(Role.OFFICER)
    if team_user and policy == "none":
        raise Forbidden("the leaderboard is shown to officers only")
    results: dict[tuple[int, str], list[RunResult]] = defaultdict(list)
    names = {team_id: name for team_id, name in db.session.execute(select(Team.id, Team.name))}
    for team_id, name in names.items():
        results[(team_id, name)] = []
    # Columns, not rows: a season's hundreds of runs rank without building an object each.
    finished = db.session.execute(
        select(
            Run.team_id,
            Run.score,
            Run.uplink_bits_used,
            Run.sim_seconds,
            Run.end_reason,
            Task.uplink_bits,
            Task.timeout_s,
        )
        .join(Task, Run.task_id == Task.id)
        .outerjoin(Phase, Task.phase_id == Phase.id)
        .where(
            Run.state == RunState.FINISHED,
            Run.invalidated_at.is_(None),
            verification.ranks(config),
            ranked_tasks(team_user),
        )
    )
    for run in finished:
        results[(run.team_id, names[run.team_id])].append(
            RunResult(
                checkpoints=run.score,
                uplink_cap_bits=run.uplink_bits,
                uplink_used_bits=run.uplink_bits_used,
                timeout_s=run.timeout_s,
                sim_seconds=run.sim_seconds,
                complete=run.end_reason == "complete",
            )
        )
    invalidated = dict(
        db.session.execute(  # type: ignore[arg-type]
            select(Run.team_id, func.count())
            .where(Run.state == RunState.FINISHED, Run.invalidated_at.is_not(None))
            .group_by(Run.team_id)
        ).all()
    )
    counted = (Run.state == RunState.FINISHED, Run.invalidated_at.is_(None))
    unverified, held = (
        dict(
            db.session.execute(  # type: ignore[arg-type]
                select(Run.team_id, func.count()).where(*counted, which).group_by(Run.team_id)
            ).all()
        )
        for which in (verification.unverified(), verification.held())
    )
    if not config.rank_unverified:
        unverified = {}  # not ranked: nothing on the board is unverified
    standings = rank(results, invalidated, unverified=unverified, held=held)
    if team_user and policy == "own":
        assert actor is not None
        standings = [s for s in standings if s.team_id == actor.team_id]
    return standings
