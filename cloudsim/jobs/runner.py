"""Run jobs: claim the row, keep a lease alive, record stage/progress/log, end in a final state."""

from __future__ import annotations

import logging
import socket
import threading
import time
import traceback
import types
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, fields
from datetime import timedelta
from typing import Any, TypeVar, Union, get_args, get_origin, get_type_hints

from celery import shared_task
from flask import current_app
from sqlalchemy import Update, event, func, or_, select, update
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import ORMExecuteState, Session
from sqlalchemy.orm.attributes import set_committed_value

from cloudsim import logcontext
from cloudsim.busy import retry_busy
from cloudsim.errors import CloudSimError, InvalidInput, NotFound
from cloudsim.extensions import db
from cloudsim.jobs.control import JobCancelled, JobStalled
from cloudsim.jobs.heartbeat import Heartbeat, in_pool_process
from cloudsim.models import Job, JobState, utcnow

log = logging.getLogger(__name__)

# A body takes its context and its kind's payload (a Payload subclass).
JobFunction = Callable[["JobContext", Any], None]
T = TypeVar("T")
JOB_KINDS: dict[str, JobFunction] = {}
PAYLOADS: dict[str, type[Payload]] = {}
# Kinds an admin may start by name (the API's POST /jobs); every other kind is started by the
# service that owns its rules (launching, runs, ...), never directly.
MAINTENANCE_KINDS: set[str] = set()
MASK = "***"
WROTE = "cloudsim.wrote"  # session.info: the session's transaction has written
CANCEL_POLL_SECONDS = 1.0  # how often a running job reads its cancel flag, at most
HELD = "remote step while the job's transaction holds uncommitted writes"
# Called with (job kind, stage) once a job has entered a stage. Production adds none; the
# crash tests add one that kills the worker there, to resume every kind from every stage.
STAGE_HOOKS: list[Callable[[str, str], None]] = []


class JobGone(Exception):
    """The job's row no longer exists."""


@dataclass(frozen=True)
class Payload:
    """A job's typed input, stored as JSON on its row; subclasses add plain-valued fields.

    Each field's value is checked against its annotation when the payload is made, so a job
    with a bad payload is refused at enqueue rather than failing in the worker.
    """

    def __post_init__(self) -> None:
        hints = get_type_hints(type(self))
        for field in fields(self):
            value = getattr(self, field.name)
            expected = hints[field.name]
            if not _is_a(value, expected):
                wanted = expected.__name__ if isinstance(expected, type) else str(expected)
                raise InvalidInput(
                    f"{type(self).__name__}.{field.name} must be {wanted}, not {value!r}"
                )

    def about(self) -> tuple[str, int] | None:
        """Return (type, id) of the row the job is about, which the job list shows."""
        return None

    def to_params(self) -> dict[str, Any]:
        """Return the payload as the job row's JSON."""
        return asdict(self)

    @classmethod
    def from_job(cls: type[P], job: Job) -> P:
        """Return a job row's payload; rows queued before payloads existed name it by target."""
        values: dict[str, Any] = dict(job.params or {})
        if job.target_type is not None:
            values.setdefault(f"{job.target_type}_id", job.target_id)
        try:
            return cls(**{f.name: values[f.name] for f in fields(cls) if f.name in values})
        except TypeError as exc:
            problem = f"job {job.id}: its payload does not fit {cls.__name__}: {exc}"
            raise CloudSimError(problem) from None


P = TypeVar("P", bound=Payload)


def _is_a(value: object, annotation: Any) -> bool:
    """Tell whether a plain value fits a payload field's annotation (int, str, X | None, ...)."""
    if get_origin(annotation) in (Union, types.UnionType):
        return any(_is_a(value, arm) for arm in get_args(annotation))
    if annotation is type(None):
        return value is None
    if annotation is float:
        return isinstance(value, int | float) and not isinstance(value, bool)
    if annotation is int:
        return isinstance(value, int) and not isinstance(value, bool)
    return isinstance(value, annotation)


def job_kind(
    name: str, *, payload: type[Payload] = Payload, maintenance: bool = False
) -> Callable[[JobFunction], JobFunction]:
    """Register a function as the body of jobs of this kind, taking `payload`; idempotent."""

    def register(fn: JobFunction) -> JobFunction:
        JOB_KINDS[name] = fn
        PAYLOADS[name] = payload
        if maintenance:
            MAINTENANCE_KINDS.add(name)
        return fn

    return register


class JobContext:
    """What a job body uses to report: stages, progress, log lines (with secrets masked).

    Reports go to the job row through their own short transactions, never through the body's
    session, so they never commit the body's half-done domain changes. The body's changes are
    committed by the runner when the body returns, and at `checkpoint()`s.
    """

    def __init__(self, job: Job, secrets: Iterable[str] = ()) -> None:
        self.job = job
        self._secrets = [s for s in secrets if s]
        self._job_id = job.id
        self._engine = db.engine
        self._session = db.session()  # the body's session, also seen from its worker threads
        self._pending: list[tuple[dict[str, object], str]] = []
        self._lock = threading.Lock()
        self.last_progress = time.monotonic()  # what the watchdog looks at
        # the stage as the body last entered it, readable from the watchdog's thread (the
        # row's attribute may be expired there, and loading it needs the body's app context)
        self.current_stage: str = job.stage or ""
        self.stalled: str | None = None  # the watchdog's reason to stop
        self._cancelled: str | None = job.cancel_reason
        self._cancel_read = 0.0
        self._warned_held = False

    def interrupted(self) -> str | None:
        """Return why the job must stop now (cancelled, or stalled), or None: what an SSH
        executor asks before each remote step, from any thread, and every second in one."""
        if self._session.info.get(WROTE) and not self._warned_held:
            # a bug to fix where it happens (checkpoint() before talking to machines): on
            # SQLite every other writer, the web's included, waits for this transaction
            self._warned_held = True
            log.warning("job %s: %s", self._job_id, HELD)
            self.log(f"warning: {HELD}")
        return self._reason()

    def _reason(self) -> str | None:
        if self.stalled is not None:
            return self.stalled
        if self._cancelled is None and time.monotonic() - self._cancel_read >= CANCEL_POLL_SECONDS:
            self._cancel_read = time.monotonic()
            try:
                with self._engine.connect() as conn:
                    self._cancelled = conn.scalar(
                        select(Job.cancel_reason).where(Job.id == self._job_id)
                    )
            except OperationalError:
                pass  # busy: read again at the next step
        return None if self._cancelled is None else f"cancelled: {self._cancelled}"

    def check(self) -> None:
        """Stop the job here (raise) when it was cancelled or stalled."""
        reason = self._reason()
        if reason is None:
            return
        if self.stalled is not None:
            raise JobStalled(reason)
        raise JobCancelled(reason)

    def cancelled(self) -> str | None:
        """Return why the job was cancelled, read now (not a cached answer), or None."""
        with self._engine.connect() as conn:
            reason = conn.scalar(select(Job.cancel_reason).where(Job.id == self._job_id))
        self._cancelled = reason or self._cancelled
        return self._cancelled

    def stall(self, reason: str) -> None:
        """Have the job stop at its next remote step (the watchdog's call)."""
        self.stalled = reason

    def load(self, model: type[T], row_id: int) -> T:
        """Return a row the payload names; fail loudly when it is gone (a job takes an id and
        reloads its row, never an object)."""
        row = db.session.get(model, row_id)
        if row is None:
            noun = getattr(model, "__tablename__", model.__name__).rstrip("s")
            raise NotFound(f"{noun} {row_id} no longer exists")
        return row

    def mask(self, *secrets: str) -> None:
        """Never show these strings in the job's log or error."""
        self._secrets.extend(s for s in secrets if s)

    def masked(self, text: str) -> str:
        """Return text with every registered secret replaced."""
        for secret in sorted(self._secrets, key=len, reverse=True):
            text = text.replace(secret, MASK)
        return text

    def log(self, message: str) -> None:
        """Append timestamped lines to the job log."""
        self.line_sink()("", message)

    def line_sink(self) -> Callable[[str, str], None]:
        """Return a thread-safe `(source, line)` logger that appends to the job row."""

        def append(source: str, message: str) -> None:
            stamp = utcnow().strftime("%H:%M:%S")
            prefix = f"[{source}] " if source else ""
            lines = self.masked(message).rstrip("\n").splitlines() or [""]
            self._report({}, "".join(f"{stamp} {prefix}{line}\n" for line in lines))

        return append

    def stage(self, name: str, progress: int | None = None) -> None:
        """Enter a named stage, optionally setting progress (0-100); a cancelled or stalled
        job stops here instead."""
        self.check()
        self.current_stage = name
        values: dict[str, object] = {"stage": name}
        if progress is not None:
            values["progress"] = max(0, min(100, progress))
        self._report(values, "")
        self.log(f"== {name}")
        for hook in STAGE_HOOKS:
            hook(self.job.kind, name)

    def progress(self, percent: int) -> None:
        """Set overall progress (0-100)."""
        self._report({"progress": max(0, min(100, percent))}, "")

    def checkpoint(self) -> None:
        """Commit the body's domain changes so far: what exists outside the database (a cloud
        node, a network) is recorded the moment it exists, so a resumed job finds it.

        A cancelled job's changes are never committed: the flag is read in the same
        transaction (on SQLite, once it wrote, the one that sets the flag waits for this one).
        """
        reason = db.session.scalar(select(Job.cancel_reason).where(Job.id == self._job_id))
        if reason is not None:
            db.session.rollback()
            self._cancelled = reason
            raise JobCancelled(f"cancelled: {reason}")
        db.session.commit()
        self.flush_reports()

    def flush_reports(self) -> None:
        """Write the reports held back while the body's transaction held SQLite's write lock."""
        with self._lock:
            pending, self._pending = self._pending, []
            if pending:
                retry_busy(lambda: self._write(pending))

    def fold_reports_into(self, job: Job) -> None:
        """Put the held-back reports into the job row's own update (its final commit)."""
        with self._lock:
            pending, self._pending = self._pending, []
        text = "".join(t for _, t in pending)
        for values, _ in pending:
            for key, value in values.items():
                setattr(job, key, value)
        if text:
            job.log = Job.log.concat(text)  # type: ignore[assignment]

    def _write(self, reports: list[tuple[dict[str, object], str]]) -> None:
        with self._engine.begin() as conn:
            for values, text in reports:
                conn.execute(self._update(values, text))

    def _report(self, values: dict[str, object], text: str) -> None:
        self.last_progress = time.monotonic()
        for key, value in values.items():  # keep the body's view current without dirtying it
            set_committed_value(self.job, key, value)
        with self._lock:
            # SQLite has one writer: while the body's transaction has written, a second
            # connection would wait for it, so the report waits for the next commit instead.
            if self._engine.dialect.name == "sqlite" and self._session.info.get(WROTE):
                self._pending.append((values, text))
                return
        self.flush_reports()
        retry_busy(lambda: self._write([(values, text)]))

    def _update(self, values: dict[str, object], text: str) -> Update:
        return (
            update(Job)
            .where(Job.id == self._job_id)
            .values(**values, **({"log": Job.log.concat(text)} if text else {}))
        )


@event.listens_for(Session, "after_flush")
def _wrote(session: Session, _context: object) -> None:
    session.info[WROTE] = True


@event.listens_for(Session, "do_orm_execute")
def _bulk_write(state: ORMExecuteState) -> None:
    if state.is_insert or state.is_update or state.is_delete:
        state.session.info[WROTE] = True


@event.listens_for(Session, "after_commit")
@event.listens_for(Session, "after_rollback")
def _ended(session: Session) -> None:
    session.info.pop(WROTE, None)


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
        .values(
            state=JobState.RUNNING,
            heartbeat_at=now,
            attempts=Job.attempts + 1,
            started_at=func.coalesce(Job.started_at, now),
            error=None,
        )
        .execution_options(synchronize_session=False)
    )
    db.session.commit()
    return result.rowcount == 1  # type: ignore[attr-defined]


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
    if job.attempts > 1:
        ctx.log(f"resuming after an interrupted attempt (attempt {job.attempts})")
    # with workers on several machines, the log says which one ran (or resumed) the job
    ctx.log(f"attempt {job.attempts} on worker host {socket.gethostname()}")
    body = JOB_KINDS.get(job.kind)
    settings = current_app.config["CLOUDSIM"]
    # ending the process frees the slot only in a worker's pool process, never in a command
    can_exit = not getattr(getattr(self, "request", None), "called_directly", True)
    can_exit = can_exit and in_pool_process()
    stall = settings.job_stall_seconds
    heartbeat = Heartbeat(ctx, min(max(1.0, lease / 4), max(0.5, stall / 4)), stall, can_exit)
    heartbeat.start()
    about = logcontext.about_target(job.target_type, job.target_id)
    with logcontext.bound(job_id=job_id, **about):  # every line logged meanwhile names them
        try:
            _run_body(ctx, job, body)
        except Exception as exc:
            db.session.rollback()
            ctx.flush_reports()
            ctx.line_sink()("", traceback.format_exc())
            job = db.session.get(Job, job_id)
            assert job is not None
            reason = str(exc) if isinstance(exc, CloudSimError) else f"{type(exc).__name__}: {exc}"
            job.error = ctx.masked(reason) or type(exc).__name__
            job.state = JobState.FAILED
            job.finished_at = utcnow()
            db.session.commit()  # the runner is the job's boundary: it commits the outcome
            raise
        finally:
            heartbeat.stopped.set()
            heartbeat.join()
        ctx.log("done")
        ctx.fold_reports_into(job)
        job.state = JobState.SUCCEEDED
        job.progress = 100
        job.finished_at = utcnow()
        db.session.commit()  # the body's changes, its last reports and the job's end, at once
        return str(job.state)


def _run_body(ctx: JobContext, job: Job, body: JobFunction | None) -> None:
    """Run a job's body with its typed payload."""
    if body is None:
        raise CloudSimError(f"unknown job kind {job.kind!r}")
    body(ctx, PAYLOADS[job.kind].from_job(job))
