"""Job kinds that exist only in tests: failing, slow enough to interrupt, failing half-way."""

from __future__ import annotations

import os
import time
from pathlib import Path

from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.jobs.runner import JobContext, job_kind
from cloudsim.models import Team

SECRET = "s3cr3t-cloud-key-AKIAEXAMPLE"


@job_kind("test.fail")
def failing_job(ctx: JobContext) -> None:
    """Log and fail with a secret in both, which must never be shown."""
    ctx.mask(SECRET)
    ctx.stage("talking to the cloud", 40)
    ctx.log(f"using key {SECRET}")
    raise CloudSimError(f"cloud refused key {SECRET}")


@job_kind("test.slow")
def slow_job(ctx: JobContext) -> None:
    """Take params['steps'] steps of params['seconds'] each; record each attempt's PID."""
    marker = Path(ctx.job.params["marker_dir"]) / f"attempt-{ctx.job.attempts}"
    marker.write_text(str(os.getpid()))
    steps = int(ctx.job.params.get("steps", 5))
    for step in range(steps):
        ctx.stage(f"step {step + 1} of {steps}", int(100 * step / steps))
        time.sleep(float(ctx.job.params.get("seconds", 0.5)))


@job_kind("test.half_done")
def half_done_job(ctx: JobContext) -> None:
    """Change the domain, report progress and log, then fail: the change must not survive."""
    db.session.add(Team(name=str(ctx.job.params["team"])))
    db.session.flush()
    ctx.stage("changing things", 50)
    ctx.log("made a team")
    ctx.progress(60)
    raise CloudSimError("failed half-way")
