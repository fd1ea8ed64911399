"""Stop jobs cooperatively: cancellation asked by whatever ends their object, and the reasons
a job gives when it stops (cancelled, or stalled by the watchdog)."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable

from sqlalchemy import select, update

from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.models import Job, JobState

UNFINISHED = (JobState.QUEUED, JobState.RUNNING)


class JobStopped(CloudSimError):
    """A job stopped before its end because it was told to; the message says why."""


class JobCancelled(JobStopped):
    """What the job is about was ended (terminated) while the job ran."""


class JobStalled(JobStopped):
    """The job made no progress for longer than the watchdog allows."""


def cancel_jobs(target_type: str, target_id: int, reason: str, *, keep: Iterable[str] = ()) -> int:
    """Ask every unfinished job about a target (except kinds in `keep`) to stop at its next
    step; return how many were asked. Flushes only: the caller's commit publishes the flag."""
    result = db.session.execute(
        update(Job)
        .where(
            Job.target_type == target_type,
            Job.target_id == target_id,
            Job.state.in_(UNFINISHED),
            Job.kind.not_in(list(keep)),
            Job.cancel_reason.is_(None),
        )
        .values(cancel_reason=reason)
        .execution_options(synchronize_session=False)
    )
    return int(result.rowcount or 0)  # type: ignore[attr-defined]


def running_jobs(
    target_type: str, target_id: int, *, keep: Iterable[str] = (), besides: str = ""
) -> list[str]:
    """Return the ids of the jobs about a target still running (read on a connection of its
    own, so it sees other workers' commits)."""
    with db.engine.connect() as conn:
        return list(
            conn.scalars(
                select(Job.id).where(
                    Job.target_type == target_type,
                    Job.target_id == target_id,
                    Job.state == JobState.RUNNING,
                    Job.kind.not_in(list(keep)),
                    Job.id != besides,
                )
            )
        )


def wait_until_stopped(
    target_type: str,
    target_id: int,
    deadline: float,
    *,
    keep: Iterable[str] = (),
    besides: str = "",
    log: Callable[[str], None],
) -> list[str]:
    """Wait (at most `deadline` seconds) for the target's other jobs to stop; return those
    still running when the time is up."""
    keep = list(keep)
    ends = time.monotonic() + deadline
    running = running_jobs(target_type, target_id, keep=keep, besides=besides)
    if running:
        log(f"waiting up to {deadline:g} s for {len(running)} running job(s) to stop")
    while running and time.monotonic() < ends:
        time.sleep(0.5)  # other workers' jobs: no event to wait on across processes
        running = running_jobs(target_type, target_id, keep=keep, besides=besides)
    return running
