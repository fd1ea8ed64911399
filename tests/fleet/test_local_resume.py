"""A worker killed in the middle of a launch: the launch resumes and leaks nothing."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from celery.contrib.testing.worker import start_worker
from flask import Flask

from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.fleet import service
from cloudsim.fleet.providers import open_provider
from cloudsim.jobs.service import sweep_jobs
from cloudsim.models import ConstellationState, Job, JobState
from tests.fleet.conftest import finished, leftovers
from tests.support.servers import wait_for

PROJECT = Path(__file__).resolve().parents[2]


def _worker(config: Config) -> subprocess.Popen[bytes]:
    env = dict(
        os.environ,
        CLOUDSIM_INSTANCE_DIR=str(config.instance_dir),
        CLOUDSIM_DATABASE_URL=config.database_url,
        CLOUDSIM_REDIS_URL=config.effective_redis_url,
        CLOUDSIM_ENCRYPTION_KEYS=",".join(config.encryption_keys),
        CLOUDSIM_SECRET_KEY=config.secret_key,
        CLOUDSIM_JOB_LEASE_SECONDS=str(config.job_lease_seconds),
        CLOUDSIM_LOCAL_PREFIX=config.local_prefix,
        CLOUDSIM_LOCAL_SUBNET_POOL=config.local_subnet_pool,
        CLOUDSIM_LOCAL_PUBLIC_CIDR=config.local_public_cidr,
        PYTHONPATH=str(PROJECT),
    )
    return subprocess.Popen(
        [
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
        ],
        env=env,
        cwd=PROJECT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def _kill_worker(process: subprocess.Popen[bytes]) -> None:
    """SIGKILL the worker and its pool processes, as a crash would (not the hosts they made)."""
    children = Path(f"/proc/{process.pid}/task/{process.pid}/children").read_text().split()
    for pid in [process.pid, *map(int, children)]:
        os.kill(pid, signal.SIGKILL)
    process.wait()


def test_launch_resumes_after_the_worker_is_killed_mid_machines(
    fleet_app: Flask, fleet_config: Config
) -> None:
    process = _worker(fleet_config)
    try:
        constellation, job = service.launch(None, name="resume", kind="vrc", provider="local")

        def creating() -> bool:
            db.session.expire_all()
            return db.session.get(Job, job.id).stage == "machines"  # type: ignore[union-attr]

        wait_for(creating, 120, "the machines stage")
        time.sleep(1.5)  # some hosts booted, some half made
    finally:
        _kill_worker(process)
    db.session.expire_all()
    assert db.session.get(Job, job.id).state == JobState.RUNNING  # type: ignore[union-attr]
    with start_worker(
        fleet_app.extensions["celery"],
        pool="solo",
        perform_ping_check=False,
        loglevel="WARNING",
        shutdown_timeout=30,
    ):
        wait_for(lambda: sweep_jobs() > 0, 30, "the dead worker's lease to expire")
        done = finished(job.id)
        assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log[-3000:]}"
        assert done.attempts == 2 and "resuming after an interrupted attempt" in done.log
        db.session.refresh(constellation)
        assert constellation.state == ConstellationState.READY
        nodes = open_provider("local", fleet_config).nodes(constellation.name)
        assert sorted(n.extra["tags"]["cloudsim:machine"] for n in nodes) == [
            "fc1",
            "fc2",
            "router",
            "sim",
        ]
        finished(service.terminate(None, constellation.id).id)
    assert leftovers(fleet_config) == {"netns": [], "mounts": [], "files": []}
