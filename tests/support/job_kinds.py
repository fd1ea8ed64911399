"""Job kinds that exist only in tests: failing, slow enough to interrupt, failing half-way."""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.jobs.runner import JobContext, Payload, job_kind
from cloudsim.models import Team
from provisioners.remote.ssh import HostKeys, SSHExecutor, SSHTarget

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


@dataclass(frozen=True)
class Remote(Payload):
    """The command test.remote runs on a host, and how to reach the host."""

    host: str
    proxy_command: str  # JSON list (a payload holds plain values)
    key_file: str
    command: str
    timeout: float = 600.0


@dataclass(frozen=True)
class Stuck(Payload):
    """How long test.stuck sits in code that never reaches a remote step."""

    seconds: float = 3600.0


@job_kind("test.remote", payload=Remote)
def remote_job(ctx: JobContext, job: Remote) -> None:
    """Run one command on a host over SSH, as provisioning steps do."""
    target = SSHTarget(
        name="host",
        host=job.host,
        private_key=Path(job.key_file).read_text(),
        proxy_command=json.loads(job.proxy_command),
    )
    ctx.stage("running the command", 10)
    with SSHExecutor(HostKeys(), log_sink=ctx.line_sink(), interrupt=ctx.interrupted) as ssh:
        ssh.run(target, job.command, timeout=job.timeout)


@job_kind("test.stuck", payload=Stuck)
def stuck_job(ctx: JobContext, job: Stuck) -> None:
    """Report once, then hang where no step checks (the watchdog must end the process)."""
    ctx.stage("stuck", 10)
    time.sleep(job.seconds)


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
