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


def worker_process(config: Config, root: Path) -> subprocess.Popen[bytes]:
    """Start a prefork worker (one pool process) on the config's database and Redis.

    root is the project's folder (pytest's rootpath), where `tests.support` is imported from.
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
        PYTHONPATH=str(root),
    )
    argv = [
        sys.executable,
        "-m",
        "celery",
        "-A",
        "tests.support.worker_app",
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
    return subprocess.Popen(
        argv, env=env, cwd=root, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )


def kill_worker(process: subprocess.Popen[bytes]) -> None:
    """SIGKILL the worker and its pool processes (not what they started, e.g. hosts)."""
    children = Path(f"/proc/{process.pid}/task/{process.pid}/children").read_text().split()
    for pid in [process.pid, *map(int, children)]:
        os.kill(pid, signal.SIGKILL)
    process.wait()


def job_finished(job_id: str, timeout: float) -> Job:
    """Commit the test's work (so its jobs are sent), wait for a job to end; return its row."""
    db.session.commit()  # the test is the boundary: its commit sends the job

    def final() -> Job | None:
        db.session.expire_all()
        job = db.session.get(Job, job_id)
        return job if job is not None and job.state.final else None

    return wait_for(final, timeout, f"job {job_id} to finish")  # type: ignore[return-value]
