"""Run jobs: claim the row, keep a lease alive, record stage/progress/log, end in a final state."""

from __future__ import annotations

import logging
import threading
import traceback
from collections.abc import Callable, Iterable
from datetime import timedelta

from celery import shared_task
from flask import current_app
from sqlalchemy import or_, update

from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.models import Job, JobState, utcnow

log = logging.getLogger(__name__)

JobFunction = Callable[["JobContext"], None]
JOB_KINDS: dict[str, JobFunction] = {}
# Kinds an admin may start by name (the API's POST /jobs); every other kind is started by the
# service that owns its rules (launching, runs, ...), never directly.
MAINTENANCE_KINDS: set[str] = set()
MASK = "***"


class JobGone(Exception):
    """The job's row no longer exists."""


def job_kind(name: str, *, maintenance: bool = False) -> Callable[[JobFunction], JobFunction]:
    """Register a function as the body of jobs of this kind; it must be idempotent."""

    def register(fn: JobFunction) -> JobFunction:
        JOB_KINDS[name] = fn
        if maintenance:
            MAINTENANCE_KINDS.add(name)
        return fn

    return register


class JobContext:
    """What a job body uses to report: stages, progress, log lines (with secrets masked)."""

    def __init__(self, job: Job, secrets: Iterable[str] = ()) -> None:
        self.job = job
        self._secrets = [s for s in secrets if s]

    def mask(self, *secrets: str) -> None:
        """Never show these strings in the job's log or error."""
        self._secrets.extend(s for s in secrets if s)

    def masked(self, text: str) -> str:
        """Return text with every registered secret replaced."""
        for secret in sorted(self._secrets, key=len, reverse=True):
            text = text.replace(secret, MASK)
        return text

    def log(self, message: str) -> None:
        """Append timestamped lines to the job log, committing the session's other changes too."""
        db.session.commit()
        self.line_sink()("", message)

    def line_sink(self) -> Callable[[str, str], None]:
        """Return a thread-safe `(source, line)` logger that appends straight to the job row."""
        engine, job_id = db.engine, self.job.id

        def append(source: str, message: str) -> None:
            stamp = utcnow().strftime("%H:%M:%S")
            prefix = f"[{source}] " if source else ""
            lines = self.masked(message).rstrip("\n").splitlines() or [""]
            text = "".join(f"{stamp} {prefix}{line}\n" for line in lines)
            with engine.begin() as conn:
                conn.execute(update(Job).where(Job.id == job_id).values(log=Job.log.concat(text)))

        return append

    def stage(self, name: str, progress: int | None = None) -> None:
        """Enter a named stage, optionally setting progress (0-100)."""
        self.job.stage = name
        if progress is not None:
            self.job.progress = max(0, min(100, progress))
        self.log(f"== {name}")

    def progress(self, percent: int) -> None:
        """Set overall progress (0-100) and commit."""
        self.job.progress = max(0, min(100, percent))
        db.session.commit()


def _claim(job_id: str, lease: int) -> bool:
    """Mark the job running if it is queued or its previous worker's lease ran out."""
    now = utcnow()
    result = db.session.execute(
        update(Job)
        .where(
            Job.id == job_id,
            or_(
                Job.state == JobState.QUEUED,
                (Job.state == JobState.RUNNING)
                & or_(
                    Job.heartbeat_at.is_(None), Job.heartbeat_at < now - timedelta(seconds=lease)
                ),
            ),
        )
        .values(state=JobState.RUNNING, heartbeat_at=now, attempts=Job.attempts + 1)
        .execution_options(synchronize_session=False)
    )
    db.session.commit()
    return result.rowcount == 1  # type: ignore[attr-defined]


class _Heartbeat(threading.Thread):
    """Renew the job's lease on its own connection while the body runs."""

    def __init__(self, job_id: str, interval: float) -> None:
        super().__init__(name=f"job-heartbeat-{job_id[:8]}", daemon=True)
        self.job_id = job_id
        self.interval = interval
        self.stopped = threading.Event()
        self.engine = db.engine

    def run(self) -> None:
        while not self.stopped.wait(self.interval):
            try:
                with self.engine.begin() as conn:
                    conn.execute(
                        update(Job).where(Job.id == self.job_id).values(heartbeat_at=utcnow())
                    )
            except Exception:  # the next beat retries; the lease tolerates a missed one
                log.warning("job %s: heartbeat failed", self.job_id, exc_info=True)


@shared_task(name="cloudsim.jobs.run", bind=True, acks_late=True, reject_on_worker_lost=True)
def run_job(self: object, job_id: str) -> str:
    """Run one job to a final state; a duplicate or late delivery does nothing."""
    lease = current_app.config["CLOUDSIM"].job_lease_seconds
    if db.session.get(Job, job_id) is None:
        raise JobGone(f"job {job_id} does not exist")
    if not _claim(job_id, lease):
        state = db.session.get(Job, job_id).state  # type: ignore[union-attr]
        log.info("job %s: not claimed (state %s); skipping this delivery", job_id, state)
        return str(state)
    job = db.session.get(Job, job_id)
    assert job is not None
    ctx = JobContext(job)
    job.started_at = job.started_at or utcnow()
    job.error = None
    if job.attempts > 1:
        ctx.log(f"resuming after an interrupted attempt (attempt {job.attempts})")
    body = JOB_KINDS.get(job.kind)
    heartbeat = _Heartbeat(job_id, max(1.0, lease / 4))
    heartbeat.start()
    try:
        if body is None:
            raise CloudSimError(f"unknown job kind {job.kind!r}")
        body(ctx)
    except Exception as exc:
        db.session.rollback()
        ctx.line_sink()("", traceback.format_exc())
        job = db.session.get(Job, job_id)
        assert job is not None
        reason = str(exc) if isinstance(exc, CloudSimError) else f"{type(exc).__name__}: {exc}"
        job.error = ctx.masked(reason) or type(exc).__name__
        job.state = JobState.FAILED
        job.finished_at = utcnow()
        db.session.commit()
        raise
    finally:
        heartbeat.stopped.set()
        heartbeat.join()
    ctx.log("done")
    job.state = JobState.SUCCEEDED
    job.progress = 100
    job.finished_at = utcnow()
    db.session.commit()
    return str(job.state)
