"""Benchmark run log collection: a large state log copied off `sim`, verified and stored.

Needs root. Launches a local `simple` constellation, writes a run's logs on its `sim` (the
state log SIZE_MB of random bytes), then times collect_logs twice: the first copy (remote
sha256sum, SFTP stream, local checksum, store) and the second (checksums only: nothing is
fetched again). Prints MB/s and the worker's peak memory growth. Usage:
python -m bench.run_logs [SIZE_MB]
"""

from __future__ import annotations

import os
import resource
import shlex
import shutil
import sys
import tempfile
import time
from pathlib import Path

from celery.contrib.testing.worker import start_worker

from cloudsim.app import create_app
from cloudsim.auth.policy import SYSTEM
from cloudsim.competition.artifacts import RUN_LOGS, LogStore, collect_logs, run_dir
from cloudsim.competition.jobs import machines
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations import service
from cloudsim.models import Job, Run, RunState, Task, Team, utcnow
from cloudsim.providers.service import open_provider
from tests.support.servers import RedisServer


def main() -> None:
    if os.geteuid() != 0:
        raise SystemExit("bench/run_logs.py needs root (the local provider makes namespaces)")
    size_mb = int(sys.argv[1]) if len(sys.argv) > 1 else 512
    instance = Path(tempfile.mkdtemp(prefix="cloudsim-bench-logs-"))
    redis = RedisServer(instance / "redis")
    env = {
        "CLOUDSIM_INSTANCE_DIR": str(instance),
        "CLOUDSIM_REDIS_URL": redis.url(),
        "CLOUDSIM_LOCAL_PREFIX": "csbenchlog",
        "CLOUDSIM_LOCAL_SUBNET_POOL": "10.215.0.0/16",
        "CLOUDSIM_LOCAL_PUBLIC_CIDR": "198.18.15.0/24",
        "CLOUDSIM_LOG_LEVEL": "WARNING",
    }
    config = Config.from_env(env)
    app = create_app(config)
    try:
        with app.app_context():
            db.create_all()
            _bench(app, config, size_mb)
    finally:
        with app.app_context():
            driver = open_provider("local", config).driver
            for node in driver.list_nodes():
                driver.destroy_node(node)
            for network in driver.ex_list_networks():
                driver.ex_destroy_network(network)
        redis.stop()
        shutil.rmtree(instance)  # the stored copy of the state log is as large as SIZE_MB


def _bench(app: object, config: Config, size_mb: int) -> None:
    team = Team(name="Bench")
    db.session.add(team)
    db.session.commit()
    celery = app.extensions["celery"]  # type: ignore[attr-defined]
    with start_worker(celery, pool="threads", concurrency=2, perform_ping_check=False):
        constellation, job = service.launch(
            SYSTEM, name="logs", kind="simple", provider="local", team_id=team.id
        )
        while not job.state.final:
            time.sleep(0.5)
            db.session.expire_all()
            job = db.session.get(Job, job.id)  # type: ignore[assignment]
        if job.state.value != "succeeded":
            raise SystemExit(f"launch failed: {job.error}")
    now = utcnow()
    task = Task(
        team_id=team.id,
        name="bench",
        world="vrc_task_2",
        window_start=now,
        window_stop=now,
        uplink_bits=0,
        downlink_bits=0,
    )
    db.session.add(task)
    db.session.flush()
    run = Run(
        task_id=task.id, team_id=team.id, constellation_id=constellation.id, state=RunState.STOPPING
    )
    db.session.add(run)
    db.session.commit()
    folder = shlex.quote(run_dir(run.id))
    with machines(run, config) as reach:
        small = " ".join(
            f"{folder}/{log.filename}"
            for log in RUN_LOGS
            if log.machine == "sim" and log.filename != "state.msgpack"
        )
        reach.executor.run(
            reach.sim,
            f"mkdir -p {folder} && touch {small} && "
            f"head -c {size_mb}M /dev/urandom > {folder}/state.msgpack",
            timeout=600,
        )
        store = LogStore(config)
        peak_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        for label in ("first copy", "again (resume)"):
            started = time.perf_counter()
            problems = collect_logs(
                run, reach.executor, reach.by_role(), store, config.instance_dir / "staging", print
            )
            seconds = time.perf_counter() - started
            if problems:
                raise SystemExit(f"collection failed: {problems}")
            print(
                f"{label}: {size_mb} MB state log in {seconds:.1f} s = {size_mb / seconds:.0f} MB/s"
            )
        grown = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - peak_before
        print(f"peak memory growth while collecting: {grown / 1024:.0f} MB")


if __name__ == "__main__":
    main()
