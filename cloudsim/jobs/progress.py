"""Where a job is: its current step and since when, read from the runner's stage log lines."""

from __future__ import annotations

import re
from datetime import UTC, datetime, time, timedelta

from cloudsim.models import Job

# JobContext.stage logs "HH:MM:SS == stage" as it enters a stage: the one record of when
STAGE_LINE = re.compile(r"^(\d\d:\d\d:\d\d) == ", re.MULTILINE)


def step_since(job: Job | None) -> str | None:
    """Return when the job entered its current stage (ISO 8601), None without a job."""
    if job is None:
        return None
    entered = STAGE_LINE.findall(job.log or "")
    if not entered:
        return job.updated_at.isoformat()
    at = datetime.combine(job.updated_at.date(), time.fromisoformat(entered[-1]), UTC)
    if at > job.updated_at + timedelta(seconds=1):  # the stage began before midnight
        at -= timedelta(days=1)
    return at.isoformat()


def job_step(job: Job | None) -> dict[str, str | None]:
    """Return a job's kind, state, current step and since when (all None without a job)."""
    if job is None:
        return {"job_kind": None, "job_state": None, "step": None, "step_since": None}
    return {
        "job_kind": job.kind,
        "job_state": job.state.value,
        "step": job.stage or None,
        "step_since": step_since(job),
    }
