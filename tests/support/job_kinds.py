"""Job kinds that exist only in tests: failing, slow enough to interrupt, failing half-way."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.jobs.runner import JobContext, Payload, job_kind
from cloudsim.models import Team

SECRET = "s3cr3t-cloud-key-AKIAEXAMPLE"


@dataclass(frozen=True)
class Slow(Payload):
    """How long test.slow takes and where it marks each attempt."""

    marker_dir: str
    steps: int = 5
    seconds: float = 0.5


@dataclass(frozen=True)
class HalfDone(Payload):
    """The team test.half_done adds before failing."""

    team: str


@job_kind("test.fail")
def failing_job(ctx: JobContext, _: Payload) -> None:
    """Log and fail with a secret in both, which must never be shown."""
    ctx.mask(SECRET)
    ctx.stage("talking to the cloud", 40)
    ctx.log(f"using key {SECRET}")
    raise CloudSimError(f"cloud refused key {SECRET}")


@job_kind("test.slow", payload=Slow)
def slow_job(ctx: JobContext, job: Slow) -> None:
    """Take `steps` steps of `seconds` each; record each attempt's PID."""
    marker = Path(job.marker_dir) / f"attempt-{ctx.job.attempts}"
    marker.write_text(str(os.getpid()))
    for step in range(job.steps):
        ctx.stage(f"step {step + 1} of {job.steps}", int(100 * step / job.steps))
        time.sleep(job.seconds)


@job_kind("test.half_done", payload=HalfDone)
def half_done_job(ctx: JobContext, job: HalfDone) -> None:
    """Change the domain, report progress and log, then fail: the change must not survive."""
    db.session.add(Team(name=job.team))
    db.session.flush()
    ctx.stage("changing things", 50)
    ctx.log("made a team")
    ctx.progress(60)
    raise CloudSimError("failed half-way")
