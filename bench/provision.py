"""Benchmark provisioning on the local provider: one vrc constellation, three at once, terminate.

Needs root. Starts a private Redis and an in-process Celery worker (3 threads) on a fresh
instance folder; the simulator's wheelhouse is built first and timed on its own (a real
installation builds it once and caches it). Usage: python -m bench.provision
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from datetime import datetime
from pathlib import Path

from celery.contrib.testing.worker import start_worker

from cloudsim.app import create_app
from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations import service
from cloudsim.launched_constellations.software import preinstall
from cloudsim.models import Job
from cloudsim.providers.service import open_provider
from constellations.definition import load_kind
from constellations.plans.software import build_wheelhouse, distribution_source
from tests.support.servers import bench_redis


def wait(job_ids: list[str]) -> float:
    """Wait for the jobs; return the seconds until the last one ended (fail loudly)."""
    db.session.commit()  # the caller's boundary: the commit sends the jobs
    started = time.perf_counter()
    while True:
        db.session.expire_all()
        jobs = [db.session.get(Job, job_id) for job_id in job_ids]
        if all(job is not None and job.state.final for job in jobs):
            failed = [job for job in jobs if job and job.state.value == "failed"]
            if failed:
                raise SystemExit(f"job failed: {failed[0].error}")
            return time.perf_counter() - started
        time.sleep(0.2)


def _span(job_id: str) -> tuple[datetime, datetime]:
    """Return when a finished job started and ended."""
    job = db.session.get(Job, job_id)
    assert job is not None and job.started_at is not None and job.finished_at is not None
    return job.started_at, job.finished_at


def main() -> None:
    if os.geteuid() != 0:
        raise SystemExit("bench/provision.py needs root (the local provider makes namespaces)")
    instance = Path(tempfile.mkdtemp(prefix="cloudsim-bench-provision-"))
    redis = bench_redis(instance)
    env = {
        "CLOUDSIM_INSTANCE_DIR": str(instance),
        "CLOUDSIM_REDIS_URL": redis.url(),
        "CLOUDSIM_LOCAL_PREFIX": "csbench",
        "CLOUDSIM_LOCAL_SUBNET_POOL": "10.214.0.0/16",
        "CLOUDSIM_LOCAL_PUBLIC_CIDR": "198.18.14.0/24",
        "CLOUDSIM_LOG_LEVEL": "WARNING",
    }
    app = create_app(Config.from_env(env))
    try:
        with app.app_context():
            db.create_all()
            started = time.perf_counter()
            build_wheelhouse(
                distribution_source("drcsim"),
                instance / "wheelhouse",
                app.config["CLOUDSIM"].machine_python,
            )
            wheelhouse = time.perf_counter() - started
            started = time.perf_counter()
            # as an installation does once: the machines' image gets the wheelhouses installed
            driver = open_provider("local", app.config["CLOUDSIM"]).driver
            preinstall(print, driver, load_kind("vrc"), app.config["CLOUDSIM"])
            layers = time.perf_counter() - started
            with start_worker(
                app.extensions["celery"],
                pool="threads",
                concurrency=3,
                perform_ping_check=False,
                loglevel="WARNING",
                shutdown_timeout=60,
            ):
                _, job = service.launch(SYSTEM, name="bench-one", kind="vrc", provider="local")
                one = wait([job.id])
                names = [f"bench-{n}" for n in ("a", "b", "c")]
                jobs = [
                    service.launch(SYSTEM, name=n, kind="vrc", provider="local")[1].id
                    for n in names
                ]
                three = wait(jobs)
                spans = [_span(job_id) for job_id in jobs]
                overlap = min(end for _, end in spans) - max(start for start, _ in spans)
                terminate_one = wait([service.terminate(SYSTEM, "bench-one").id])
                terminate_three = wait([service.terminate(SYSTEM, n).id for n in names])
    finally:
        with app.app_context():
            # whatever a failed run left behind
            open_provider("local", app.config["CLOUDSIM"]).driver.ex_sweep()  # type: ignore[attr-defined]
        redis.stop()
        shutil.rmtree(instance, ignore_errors=True)
    print("provisioning benchmark (local provider, vrc = router + sim + fc1 + fc2)")
    print(f"  wheelhouse build (once, cached)        {wheelhouse:6.1f} s")
    print(f"  image layers (once, until no host)     {layers:6.1f} s")
    print(f"  one constellation to ready             {one:6.1f} s   (target < 60 s)")
    print(
        f"  three at once to ready                 {three:6.1f} s   "
        f"ratio {three / one:.2f} x one (target < 2)"
    )
    print(
        f"  the three launches ran side by side for {overlap.total_seconds():.1f} s "
        f"(CPU-bound on {os.cpu_count()} cores: host boots, offline installs, self-tests)"
    )
    print(f"  terminate one                          {terminate_one:6.1f} s")
    print(f"  terminate three at once                {terminate_three:6.1f} s")


if __name__ == "__main__":
    main()
