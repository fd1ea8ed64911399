"""A run's life: the one place its state changes and the jobs each change starts are enqueued.

starting -> running -> stopping -> finished | error; a start that fails goes to stopping; a
stop that keeps failing goes to needs_review, which an officer settles (finished or error).
The service checks who may ask and what is allowed; the job bodies and the beat do the work;
all of them call here to move the state.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sqlalchemy import update

from cloudsim.auth.policy import SYSTEM, Actor
from cloudsim.error_codes import (
    RUN_END_UNKNOWN,
    RUN_REVIEWED_FAILED,
    RUN_ROUTER_FAULT,
    RUN_START_FAILED,
    RUN_STOP_FAILED,
)
from cloudsim.extensions import db
from cloudsim.jobs.runner import Payload
from cloudsim.jobs.service import enqueue
from cloudsim.models import Run, RunState, utcnow
from cloudsim.notifications.service import notify_run_event, run_ended_event


@dataclass(frozen=True)
class RunJob(Payload):
    """The payload of every run job: which run."""

    run_id: int

    def about(self) -> tuple[str, int]:
        return ("run", self.run_id)


def new_run(**fields: Any) -> Run:
    """Return a new run, `starting`."""
    return Run(**fields, state=RunState.STARTING)


def start(actor: Actor, run: Run) -> None:
    """Start the job that starts a new run."""
    enqueue("run.start", actor, RunJob(run.id), team_id=run.team_id)


def enqueue_stop(run: Run) -> None:
    """Start the job that stops a run: the one place it is started from."""
    enqueue("run.stop", SYSTEM, RunJob(run.id), team_id=run.team_id)


def request_stop(run: Run, reason: str) -> bool:
    """Record why a run ends and start its stop job once; return whether this call started it.

    A run still starting is stopped by its start job when it gets there.
    """
    db.session.execute(
        update(Run)
        .where(Run.id == run.id, Run.stop_reason.is_(None))
        .values(stop_reason=reason)
        .execution_options(synchronize_session=False)
    )
    moved = db.session.execute(
        update(Run)
        .where(Run.id == run.id, Run.state == RunState.RUNNING)
        .values(state=RunState.STOPPING)
        .execution_options(synchronize_session=False)
    )
    db.session.refresh(run)
    if moved.rowcount != 1:  # type: ignore[attr-defined]
        return False
    enqueue_stop(run)
    return True


def start_failed(run: Run, error: str) -> None:
    """Record why a run could not start and start stopping what was started."""
    run.error, run.error_code = error, RUN_START_FAILED
    run.stop_reason = run.stop_reason or "error"
    run.state = RunState.STOPPING
    enqueue_stop(run)


def running(run: Run) -> None:
    """Mark a started run running (since its simulator started, when the job knows it)."""
    run.state = RunState.RUNNING
    run.running_at = run.running_at or utcnow()


def stop_requested_while_starting(run: Run) -> None:
    """Stop a run that was asked to stop while it was starting (no-op otherwise)."""
    if run.stop_reason is not None:
        request_stop(run, run.stop_reason)


def stopped_while_starting(run: Run) -> None:
    """Hand a run asked to stop before its start finished to its stop job, which undoes what
    the start did (an armed router, a started simulator)."""
    db.session.refresh(run, ["stop_reason"])
    run.state = RunState.STOPPING
    enqueue_stop(run)


def stopping(run: Run) -> None:
    """Mark a run as being stopped by its stop job."""
    run.state = RunState.STOPPING


def ended(run: Run, error: str | None, failed: bool) -> None:
    """Mark a stopped run finished (or error), freeing its constellation."""
    if failed:
        run.error_code = run.error_code or RUN_STOP_FAILED
    elif run.error_code != RUN_ROUTER_FAULT:  # a recovered router fault stays a note
        run.error_code = None
    run.error = error
    run.state = RunState.ERROR if failed else RunState.FINISHED
    run.end_reason = run.end_reason or run.stop_reason
    run.finished_at = utcnow()
    run.active_constellation_id = None


def needs_review(run: Run, why: str) -> None:
    """Hand a run whose end cannot be established to the officers, never leaving it live."""
    run.state = RunState.NEEDS_REVIEW
    run.error, run.error_code = why, RUN_END_UNKNOWN
    run.review_since = utcnow()
    # here, not in the callers: the stop job and the supervisor both hand runs over
    notify_run_event(run, "needs_review")


def settled(run: Run, accept: bool, end_reason: str) -> None:
    """Record an officer's decision on a run in review: its end accepted, or failed."""
    run.state = RunState.FINISHED if accept else RunState.ERROR
    run.end_reason = end_reason if accept else run.end_reason
    if not accept:
        run.error_code = RUN_REVIEWED_FAILED
    run.finished_at = utcnow()
    run.active_constellation_id = None
    notify_run_event(run, run_ended_event(run))  # the end people were told would follow
