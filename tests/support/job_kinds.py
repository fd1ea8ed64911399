"""Job kinds that exist only in tests: one that fails, one that is slow enough to interrupt."""

from __future__ import annotations

import os
import time
from pathlib import Path

from cloudsim.errors import CloudSimError
from cloudsim.jobs.runner import JobContext, job_kind

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
