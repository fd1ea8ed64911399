"""Benchmark a storm of runs (start and stop jobs) drained by one worker machine, then by two.

Needs root. The worker machines are local hosts with CloudSim installed from its source
bundle (as the `cloudsim` kind installs it), each running `cloudsim worker` (2 processes)
against the master's PostgreSQL and Redis (password logins, over the LAN through relays at
the gateway) and an S3 object store (moto) for the run logs, exactly as in
tests/cli/test_worker_host.py. Each run's sim is a minimal stand-in host
(tests/support/lightweight_runs.py) the workers reach by its LAN address; the run's stop job
collects its score log into the store and scores it.

Figures, from one process and one run of this script: the wall time from queuing the
storm's start jobs to the last stop job's end (every worker answering a ping before it
begins), with one worker machine (the reference) and with two, the jobs each machine ran
(from the jobs' logs), and the ratio. All hosts share this machine's cores: a second worker
machine adds job slots, so the ratio shows the jobs' waits (SSH round trips, the store, the
database) overlapping, not more CPU.

Usage: python -m bench.scaleout [--runs 12]
"""

from __future__ import annotations

import argparse
import logging
import os
import re
import shutil
import subprocess
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from celery import Celery
from flask import current_app
from moto.server import ThreadedMotoServer
from sqlalchemy import select

from cloudsim.app import create_app
from cloudsim.auth.policy import SYSTEM
from cloudsim.competition import runs
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import Job, JobState, Role, Run, RunState, Task, User
from cloudsim.people import service as people_service
from cloudsim.providers.service import open_provider
from tests.competition.support import open_task
from tests.support.worker_hosts import (
    Host,
    MasterServers,
    boot_hosts,
    cloudsim_bundle,
    install_cloudsim,
    master_servers,
    reachable_from_lan,
    sim_constellation,
    sim_stand_in,
    start_worker,
    stop_worker,
    worker_env,
    write_run_logs,
)

PREFIX = "csscaleb"
GATEWAY = "198.18.42.1"
WORKER_HOST = re.compile(r"on worker host (\S+)")


def main() -> None:
    if os.geteuid() != 0:
        raise SystemExit("bench/scaleout.py needs root (local hosts are namespaces)")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=12, help="runs in each storm")
    args = parser.parse_args()
    print(f"load before: {_uptime()}")
    logging.getLogger("werkzeug").setLevel(logging.ERROR)
    scratch = Path(tempfile.mkdtemp(prefix=f"{PREFIX}-"))
    moto = ThreadedMotoServer(ip_address="127.0.0.1", port=0, verbose=False)
    moto.start()
    try:
        with master_servers(scratch, moto.get_host_and_port()[1], GATEWAY) as servers:
            config = Config.from_env(
                {
                    "CLOUDSIM_INSTANCE_DIR": str(scratch / "instance"),
                    "CLOUDSIM_LOG_LEVEL": "WARNING",
                    "CLOUDSIM_LOCAL_PREFIX": PREFIX,
                    "CLOUDSIM_LOCAL_SUBNET_POOL": "10.242.0.0/16",
                    "CLOUDSIM_LOCAL_PUBLIC_CIDR": "198.18.42.0/24",
                    "CLOUDSIM_JOB_LEASE_SECONDS": "10",
                },
                **servers.master,
            )
            app = create_app(config)
            try:
                with app.app_context():
                    db.create_all()
                    _bench(config, servers, scratch, args.runs)
            finally:
                open_provider("local", config).driver.ex_sweep()  # type: ignore[attr-defined]
    finally:
        moto.stop()
        shutil.rmtree(scratch, ignore_errors=True)
    print(f"load after: {_uptime()}")


def _bench(config: Config, servers: MasterServers, scratch: Path, count: int) -> None:
    started = time.monotonic()
    first, second, sim = boot_hosts(
        config, "lan", {"worker1": "minimal", "worker2": "minimal", "sim": "minimal"}
    )
    sim_stand_in(sim)
    print(f"3 hosts up in {time.monotonic() - started:.1f} s")
    started = time.monotonic()
    bundle = cloudsim_bundle(scratch / "wheelhouse", config.machine_python)
    with ThreadPoolExecutor(max_workers=2) as pool:
        list(pool.map(lambda host: install_cloudsim(host, bundle), [first, second]))
    print(
        f"CloudSim bundled and installed on 2 worker machines in {time.monotonic() - started:.1f} s"
    )
    env = worker_env(config, servers, bundle)
    celery = current_app.extensions["celery"]
    figures: dict[int, float] = {}
    with reachable_from_lan(f"{PREFIX}-s-public", GATEWAY, servers.ports):
        for machines in ([first], [second, first]):
            pids = [(host, start_worker(host, env)) for host in machines]
            try:
                _wait_ready(
                    celery, [f"cloudsim@{host.run('hostname').strip()}" for host in machines]
                )
                seconds, by_host = _storm(sim, count, len(machines))
            finally:
                for host, pid in pids:
                    stop_worker(host, pid)
            figures[len(machines)] = seconds
            shares = ", ".join(f"{name}: {jobs}" for name, jobs in sorted(by_host.items()))
            print(
                f"{count} runs ({2 * count} jobs), {len(machines)} worker machine(s)"
                f" x 2 processes: {seconds:6.1f} s ({2 * count / seconds:5.2f} jobs/s); jobs by"
                f" machine: {shares}"
            )
    print("ratio:")
    print(f"  one worker machine / two worker machines: {figures[1] / figures[2]:6.2f}")


def _storm(sim: Host, count: int, storm: int) -> tuple[float, Counter[str]]:
    """Start `count` runs at once, then stop them all; return the wall time and who ran what."""
    users = []
    for index in range(count):
        team = people_service.create_team(SYSTEM, f"Team {storm}-{index}")
        db.session.flush()
        user = people_service.create_user(
            SYSTEM,
            email=f"u{storm}-{index}@example.org",
            role=Role.USER,
            team_id=team.id,
            password="bench-password-123",
        ).user
        sim_constellation(team.id, f"s{storm}-{index}", sim)
        open_task(team.id)
        users.append(user)
    db.session.commit()
    started = time.monotonic()
    started_runs = [runs.start_run(user, _task_of(user)) for user in users]
    db.session.commit()
    ids = [run.id for run in started_runs]
    _wait(lambda: _all(ids, "run.start"), "the start jobs")
    write_run_logs(sim, ids)
    for user, run_id in zip(users, ids, strict=True):
        runs.stop_run(user, run_id)
    db.session.commit()
    _wait(lambda: _all(ids, "run.stop"), "the stop jobs")
    seconds = time.monotonic() - started
    db.session.rollback()
    finished = db.session.scalars(select(Run).where(Run.id.in_(ids))).all()
    assert all(run.state == RunState.FINISHED for run in finished), [r.error for r in finished]
    jobs = db.session.scalars(
        select(Job).where(Job.target_type == "run", Job.target_id.in_(ids))
    ).all()
    return seconds, Counter(m.group(1) for job in jobs for m in WORKER_HOST.finditer(job.log))


def _task_of(user: User) -> int:
    return int(db.session.scalars(select(Task.id).where(Task.team_id == user.team_id)).one())


def _wait_ready(celery: Celery, names: list[str]) -> None:
    """Wait until every named worker answers a ping: the storm times jobs, not start-ups."""

    def ready() -> bool:
        replies = celery.control.ping(destination=names, timeout=1.0)
        return {name for reply in replies for name in reply} >= set(names)

    _wait(ready, f"workers {', '.join(names)} to answer")


def _all(run_ids: list[int], kind: str) -> bool:
    db.session.rollback()
    jobs = db.session.scalars(
        select(Job).where(Job.kind == kind, Job.target_type == "run", Job.target_id.in_(run_ids))
    ).all()
    failed = [f"{job.id}: {job.error}" for job in jobs if job.state == JobState.FAILED]
    if failed:
        raise SystemExit(f"{kind} failed: {failed}")
    return len(jobs) == len(run_ids) and all(job.state == JobState.SUCCEEDED for job in jobs)


def _wait(condition: Callable[[], bool], what: str, timeout: float = 900) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise SystemExit(f"timed out waiting for {what}")
        time.sleep(0.1)


def _uptime() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True, check=False).stdout.strip()


if __name__ == "__main__":
    main()
