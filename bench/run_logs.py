"""Benchmark run log collection against a plain OpenSSH pipe of the same file, same route.

Needs root. Launches a local `simple` constellation, writes a run's logs on its `sim` (the
state log SIZE_MB of random bytes, 1 GiB by default), then times, on that file: an OpenSSH
pipe (`ssh ... cat FILE > local file`, the same ssh options and route the collector uses),
collect_logs (remote checksum, OpenSSH stream hashed as it arrives, store), the pipe again,
and collect_logs once more (checksums only: nothing is fetched again). Prints both figures
side by side, their ratio (collection / mean of the two pipes), the collector's peak memory
(its own and ssh's) and the machine's load. Usage: python -m bench.run_logs [--size-mb N]
"""

from __future__ import annotations

import argparse
import os
import resource
import shlex
import shutil
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

from celery.contrib.testing.worker import start_worker

from cloudsim.app import create_app
from cloudsim.auth.policy import SYSTEM
from cloudsim.competition.artifacts import RUN_LOGS, LogStore, collect_logs, run_dir
from cloudsim.competition.jobs import Machines, machines
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations import service
from cloudsim.models import Job, Run, RunState, Task, Team, utcnow
from cloudsim.providers.service import open_provider
from provisioners.remote.ssh import SSHTarget
from provisioners.remote.ssh.openssh import OpenSSH
from tests.support.servers import bench_redis


def main() -> None:
    if os.geteuid() != 0:
        raise SystemExit("bench/run_logs.py needs root (the local provider makes namespaces)")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size-mb", type=int, default=1024, help="size of the state log, MiB")
    parser.add_argument("--rounds", type=int, default=3, help="pipe + collection pairs")
    arguments = parser.parse_args()
    instance = Path(tempfile.mkdtemp(prefix="cloudsim-bench-logs-"))
    redis = bench_redis(instance)
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
            open_provider("local", config).driver.ex_sweep()  # type: ignore[attr-defined]
            db.create_all()
            _bench(app, config, arguments.size_mb, arguments.rounds)
    finally:
        with app.app_context():
            # the bench's own prefix: whatever it left, also from a run that was killed
            open_provider("local", config).driver.ex_sweep()  # type: ignore[attr-defined]
        redis.stop()
        shutil.rmtree(instance)  # the stored copy of the state log is as large as SIZE_MB


def _bench(app: object, config: Config, size_mb: int, rounds_wanted: int) -> None:
    team = Team(name="Bench")
    db.session.add(team)
    db.session.commit()
    celery = app.extensions["celery"]  # type: ignore[attr-defined]
    with start_worker(celery, pool="threads", concurrency=2, perform_ping_check=False):
        constellation, job = service.launch(
            SYSTEM, name="logs", kind="simple", provider="local", team_id=team.id
        )
        db.session.commit()  # the bench is the boundary: the commit sends the job
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
        staging = config.instance_dir / "staging"
        staging.mkdir(parents=True, exist_ok=True)
        openssh = OpenSSH(reach.executor.host_keys)
        remote = f"{run_dir(run.id)}/state.msgpack"
        print(f"load before: {_load()}")
        peak_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        rounds = []
        for number in range(1, rounds_wanted + 1):
            piped = _pipe(openssh, reach.sim, remote, staging / "pipe.bin", size_mb)
            if number > 1:  # forget the stored state log: the next collection copies it again
                state = next(a for a in run.artifacts if a.filename == "state.msgpack")
                store.driver.delete_object(
                    store.driver.get_object(store.container_name, state.location)
                )
                run.artifacts.remove(state)  # the relationship deletes the orphan
                db.session.flush()
            collected = size_mb / _collect(run, reach, store, staging, size_mb, verbose=number == 1)
            rounds.append((piped, collected))
            print(
                f"round {number}: pipe {piped:.0f} MiB/s, collection {collected:.0f} MiB/s, "
                f"ratio {collected / piped:.2f}"
            )
        grown = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - peak_before
        started = time.perf_counter()
        if collect_logs(run, reach.executor, reach.by_role(), store, staging, _quiet):
            raise SystemExit("collecting again failed")
        again = time.perf_counter() - started
        print(f"load after: {_load()}")
        pipe = statistics.median(p for p, _ in rounds)
        collection = statistics.median(c for _, c in rounds)
        ratio = statistics.median(c / p for p, c in rounds)
        print(
            f"median of {len(rounds)} rounds: OpenSSH pipe {pipe:.0f} MiB/s | CloudSim collection "
            f"{collection:.0f} MiB/s | ratio {ratio:.2f} (each round's own pair; goal >= 0.75)"
        )
        print(
            f"collector peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f}"
            f" MB (grew {grown / 1024:.0f} MB while collecting {size_mb} MiB x {len(rounds)})"
        )
        print(f"collecting again (all stored): {again:.2f} s, nothing fetched")


def _collect(
    run: Run, reach: Machines, store: LogStore, staging: Path, size_mb: int, verbose: bool
) -> float:
    """Collect the run's logs; return the seconds it took."""
    started = time.perf_counter()
    lines: list[tuple[float, str]] = []
    problems = collect_logs(
        run,
        reach.executor,
        reach.by_role(),
        store,
        staging,
        lambda line: lines.append((time.perf_counter() - started, line)),
    )
    seconds = time.perf_counter() - started
    if problems:
        raise SystemExit(f"collection failed: {problems}")
    if verbose:
        print(f"collection: {size_mb} MiB state log (and the small logs) in {seconds:.2f} s")
        for at, line in lines:
            print(f"  {at:5.2f} s  {line}")
    return seconds


def _pipe(openssh: OpenSSH, sim: SSHTarget, remote: str, local: Path, size_mb: int) -> float:
    """Return the MiB/s of `ssh sim cat FILE > local`, the reference the collector is held to."""
    with openssh.command(sim, f"cat -- {shlex.quote(remote)}") as argv, local.open("wb") as out:
        started = time.perf_counter()
        subprocess.run(argv, stdout=out, stdin=subprocess.DEVNULL, check=True)
        seconds = time.perf_counter() - started
    local.unlink()
    return size_mb / seconds


def _load() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()


def _quiet(line: str) -> None:
    del line


if __name__ == "__main__":
    main()
