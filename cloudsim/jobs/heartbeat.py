"""Keep a running job's lease alive and watch its progress: the watchdog of stuck jobs."""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

from sqlalchemy import update

from cloudsim.extensions import db
from cloudsim.models import Job, JobState, utcnow

if TYPE_CHECKING:
    from cloudsim.jobs.runner import JobContext

log = logging.getLogger(__name__)


class Heartbeat(threading.Thread):
    """Renew the job's lease on its own connection while the body runs, and watch its progress.

    A body that reports nothing for `stall` seconds is told to stop (it does at its next
    remote step, which fails it with the reason). One that still has not stopped `stall`
    seconds later is stuck outside any step: in a worker's pool process the job is failed
    with the reason and the process ends, so that the worker replaces it and the slot is free.
    """

    def __init__(self, ctx: JobContext, interval: float, stall: float, can_exit: bool) -> None:
        super().__init__(name=f"job-heartbeat-{ctx.job.id[:8]}", daemon=True)
        self.ctx = ctx
        self.job_id = ctx.job.id
        self.interval = interval
        self.stall = stall
        self.can_exit = can_exit
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
            self._watch()

    def _watch(self) -> None:
        idle = time.monotonic() - self.ctx.last_progress
        if self.ctx.stalled is None and idle >= self.stall:
            reason = (
                f"stopped by the watchdog: no progress for {idle:.0f} s "
                f"(CLOUDSIM_JOB_STALL_SECONDS={self.stall:g}) in stage "
                f"{self.ctx.current_stage or 'start'!r}"
            )
            log.warning("job %s: %s", self.job_id, reason)
            self.ctx.stall(reason)
        elif self.ctx.stalled is not None and idle >= 2 * self.stall and self.can_exit:
            self._end_process()

    def _end_process(self) -> None:
        reason = f"{self.ctx.stalled}; it did not stop, so its worker process was ended"
        log.error("job %s: %s", self.job_id, reason)
        try:
            with self.engine.begin() as conn:
                conn.execute(
                    update(Job)
                    .where(Job.id == self.job_id, Job.state == JobState.RUNNING)
                    .values(state=JobState.FAILED, error=reason, finished_at=utcnow())
                )
        finally:
            os._exit(70)  # the pool replaces the process; the redelivery finds the job failed


def in_pool_process() -> bool:
    """Tell whether this is a prefork pool's child process (which its worker replaces)."""
    from billiard.process import current_process

    return current_process().name.startswith("ForkPoolWorker")


@contextmanager
def reporting_wait(
    log_line: Callable[[str], None], what: str, every: float = 30.0
) -> Iterator[None]:
    """Log "still WHAT (N s)" every `every` seconds while the block runs.

    Only for a wait bounded by a deadline of its own (a subprocess with a timeout): the
    watchdog then sees progress, and the user sees what the job is doing, instead of a
    long silent step stopped as stuck.
    """
    stop = threading.Event()
    started = time.monotonic()

    def tick() -> None:
        while not stop.wait(every):
            log_line(f"still {what} ({time.monotonic() - started:.0f} s)")

    ticker = threading.Thread(target=tick, name="job-reporting-wait", daemon=True)
    ticker.start()
    try:
        yield
    finally:
        stop.set()
        ticker.join()
