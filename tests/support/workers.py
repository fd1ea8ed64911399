"""A Celery worker in a process of its own, to be killed the way a crash kills one."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import Job
from tests.support.servers import wait_for


def worker_process(
    config: Config,
    root: Path,
    app: str = "tests.support.worker_app",
    extra_env: dict[str, str] | None = None,
    beat_schedule: Path | None = None,
) -> subprocess.Popen[bytes]:
    """Start a prefork worker (one pool process) on the config's database and Redis; with
    `beat_schedule`, the beat too, inside it (every periodic task, as `cloudsim up` sends).

    root is the project's folder (pytest's rootpath), where `tests.support` is imported from;
    app the module of its Celery app; extra_env more environment for it.
    """
    env = dict(
        os.environ,
        CLOUDSIM_INSTANCE_DIR=str(config.instance_dir),
        CLOUDSIM_DATABASE_URL=config.database_url,
        CLOUDSIM_REDIS_URL=config.effective_redis_url,
        CLOUDSIM_ENCRYPTION_KEYS=",".join(config.encryption_keys),
        CLOUDSIM_SECRET_KEY=config.secret_key,
        CLOUDSIM_JOB_LEASE_SECONDS=str(config.job_lease_seconds),
        CLOUDSIM_JOB_STALL_SECONDS=str(config.job_stall_seconds),
        CLOUDSIM_LOCAL_PREFIX=config.local_prefix,
        CLOUDSIM_LOCAL_SUBNET_POOL=config.local_subnet_pool,
        CLOUDSIM_LOCAL_PUBLIC_CIDR=config.local_public_cidr,
        # the test's own floor (a loaded machine's simulator self-test), as in-process workers
        CLOUDSIM_SIM_MIN_RTF=str(config.sim_min_rtf),
        PYTHONPATH=str(root),
        **(extra_env or {}),
    )
    argv = [
        sys.executable,
        "-m",
        "celery",
        "-A",
        app,
        "worker",
        "--pool",
        "prefork",
        "--concurrency",
        "1",
        "--loglevel",
        "WARNING",
        "--queues",
        "cloudsim",
        "--without-mingle",
        "--without-gossip",
    ]
    if beat_schedule is not None:
        argv += ["--beat", "--schedule", str(beat_schedule)]
    return subprocess.Popen(
        argv, env=env, cwd=root, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )


def kill_worker(process: subprocess.Popen[bytes]) -> None:
    """SIGKILL the worker and its pool processes (not what they started, e.g. hosts)."""
    children = Path(f"/proc/{process.pid}/task/{process.pid}/children").read_text().split()
    for pid in [process.pid, *map(int, children)]:
        os.kill(pid, signal.SIGKILL)
    process.wait()


def crash_worker(
    config: Config, root: Path, after: str = "", at: str = ""
) -> subprocess.Popen[bytes]:
    """Start a worker that SIGKILLs itself (worker and pool) right after a run job's step,
    named "KIND:STEP" (cloudsim.competition.run_steps), or as any job enters a stage, named
    "KIND:STAGE" (cloudsim.jobs.runner)."""
    return worker_process(
        config,
        root,
        app="tests.support.crash_worker_app",
        extra_env={"CLOUDSIM_TEST_CRASH_AFTER": after, "CLOUDSIM_TEST_CRASH_AT": at},
    )


def kill_worker_tree(process: subprocess.Popen[bytes]) -> None:
    """SIGKILL the worker and everything under it (pool, the processes jobs started)."""
    found, queue = [], [process.pid]
    while queue:
        pid = queue.pop()
        found.append(pid)
        for task in Path(f"/proc/{pid}/task").glob("*"):
            try:
                queue += map(int, (task / "children").read_text().split())
            except FileNotFoundError:
                continue  # gone meanwhile
    for pid in found:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            continue
    process.wait()


def job_finished(job_id: str, timeout: float) -> Job:
    """Commit the test's work (so its jobs are sent), wait for a job to end; return its row."""
    db.session.commit()  # the test is the boundary: its commit sends the job

    def final() -> Job | None:
        db.session.expire_all()
        job = db.session.get(Job, job_id)
        return job if job is not None and job.state.final else None

    return wait_for(final, timeout, f"job {job_id} to finish")  # type: ignore[return-value]
