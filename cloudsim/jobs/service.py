"""Start jobs, find the ones a person may see, and re-send jobs whose delivery was lost."""

from __future__ import annotations

import logging
import uuid
from dataclasses import fields
from datetime import timedelta

from celery import shared_task
from flask import current_app
from kombu.exceptions import OperationalError
from sqlalchemy import Select, event, func, or_, select
from sqlalchemy.orm import Session

from cloudsim.audit.service import record
from cloudsim.auth.policy import Actor, require_role, require_team_access
from cloudsim.errors import InvalidInput, NotFound
from cloudsim.extensions import db
from cloudsim.jobs.runner import JOB_KINDS, MAINTENANCE_KINDS, PAYLOADS, Payload, run_job
from cloudsim.models import Job, JobState, Role, utcnow

log = logging.getLogger(__name__)
UNSENT = "cloudsim.unsent_jobs"  # session.info: ids of jobs to send after the commit


def enqueue(
    kind: str, actor: Actor, payload: Payload | None = None, *, team_id: int | None = None
) -> Job:
    """Add a job to the session; its message is sent once the caller's transaction commits.

    The payload must be the type the kind declares (none for kinds without one). Sending after
    the commit means a worker never looks for a job row that is not there yet, and a
    rolled-back job is never sent. If the queue is down, the sweeper sends it later.
    """
    if kind not in JOB_KINDS:
        raise InvalidInput(f"unknown job kind {kind!r}; known: {', '.join(sorted(JOB_KINDS))}")
    expected = PAYLOADS[kind]
    payload = expected() if payload is None and not fields(expected) else payload
    if type(payload) is not expected:
        raise InvalidInput(
            f"a {kind} job takes a {expected.__name__}, not {type(payload).__name__}"
        )
    assert payload is not None
    target_type, target_id = payload.about() or (None, None)
    job_id = str(uuid.uuid4())
    job = Job(
        id=job_id,
        kind=kind,
        target_type=target_type,
        target_id=target_id,
        team_id=team_id,
        params=payload.to_params(),
        celery_id=job_id,
        created_by_id=actor.id,
    )
    db.session.add(job)
    record("job.start", actor, target_type="job", target_id=job_id, team_id=team_id, kind=kind)
    db.session.flush()
    db.session.info.setdefault(UNSENT, []).append(job_id)
    return job


def start_maintenance(kind: str, actor: Actor) -> Job:
    """Start a maintenance job such as diagnostics (admins); other kinds belong to services."""
    require_role(actor, Role.ADMIN, "start maintenance jobs")
    if kind not in MAINTENANCE_KINDS:
        known = ", ".join(sorted(MAINTENANCE_KINDS))
        raise InvalidInput(f"unknown maintenance job kind {kind!r}; known: {known}")
    return enqueue(kind, actor)


@event.listens_for(Session, "after_commit")
def _send_committed(session: Session) -> None:
    for job_id in session.info.pop(UNSENT, []):
        send(job_id)


@event.listens_for(Session, "after_rollback")
def _forget_rolled_back(session: Session) -> None:
    session.info.pop(UNSENT, None)


def workers_alive() -> bool:
    """Return whether any Celery worker answers a ping within a second."""
    celery = current_app.extensions["celery"]
    try:
        return bool(celery.control.ping(timeout=1.0))
    except (OperationalError, OSError):
        return False


def run_here(job_id: str) -> None:
    """Run a sent job in this process (a command whose job no worker would take); a worker
    that gets the message later finds the job done and skips it."""
    try:
        run_job(job_id)
    except Exception:
        log.info("job %s failed in-process", job_id, exc_info=True)


def send(job_id: str) -> bool:
    """Put a saved job's message on the queue; False (logged) when the broker is down."""
    try:
        run_job.apply_async(args=[job_id], task_id=job_id, retry=False)
    except (OperationalError, OSError) as exc:
        log.warning("job %s saved but not queued (%s); the sweeper will send it", job_id, exc)
        return False
    return True


def get_job(actor: Actor, job_id: str) -> Job:
    """Return a job the actor may see."""
    job = db.session.get(Job, job_id)
    if job is None:
        raise NotFound.of("job", job_id)
    require_team_access(actor, job.team_id, "job", job_id)
    return job


def visible_jobs(actor: Actor, *, state: str | None = None) -> Select[Job]:
    """Return a query for the jobs the actor may see, newest first."""
    query = select(Job).order_by(Job.created_at.desc(), Job.id)
    if not actor.has_role(Role.OFFICER):
        query = query.where(Job.team_id == actor.team_id, Job.team_id.is_not(None))
    if state:
        try:
            query = query.where(Job.state == JobState(state))
        except ValueError:
            names = ", ".join(s.value for s in JobState)
            raise InvalidInput(f"unknown job state {state!r}; choose one of {names}") from None
    return query


def queue_depths(actor: Actor) -> dict[str, dict[str, int]]:
    """Return per kind how many jobs the actor may see are queued and running (the queues)."""
    waiting = visible_jobs(actor).where(Job.state.in_((JobState.QUEUED, JobState.RUNNING)))
    counted = (
        select(Job.kind, Job.state, func.count())
        .where(Job.id.in_(waiting.with_only_columns(Job.id).order_by(None)))
        .group_by(Job.kind, Job.state)
    )
    depths: dict[str, dict[str, int]] = {}
    for kind, state, count in db.session.execute(counted):
        depths.setdefault(kind, {"queued": 0, "running": 0})[state.value] = count
    return dict(sorted(depths.items()))


def lost_jobs() -> list[Job]:
    """Return jobs never started in time, and running jobs whose worker's lease expired."""
    settings = current_app.config["CLOUDSIM"]
    now = utcnow()
    stale_queued = now - timedelta(seconds=settings.stale_job_seconds)
    expired = now - timedelta(seconds=settings.job_lease_seconds)
    return list(
        db.session.scalars(
            select(Job).where(
                or_(
                    (Job.state == JobState.QUEUED) & (Job.created_at < stale_queued),
                    (Job.state == JobState.RUNNING) & (Job.heartbeat_at < expired),
                )
            )
        )
    )


@shared_task(name="cloudsim.jobs.sweep")
def sweep_jobs() -> int:
    """Re-send every lost job (the runner's claim makes a duplicate delivery harmless)."""
    sent = 0
    for job in lost_jobs():
        log.info("job %s (%s) looks lost; sending it again", job.id, job.state)
        sent += send(job.id)
    return sent
