"""Benchmark the beat's supervision of live runs: 1, 10 and 30 runs, and one hung machine.

Needs root. Thirty `vrc` constellations do not fit on this machine, so each run is
lightweight (`tests/support/lightweight_runs.py`): a minimal local host (its own namespace,
filesystem and sshd) stands for both its sim and its router, which stay two machines on the
run's constellation (two rows, two routes, two connections, the same three commands a beat
sends in production). On the host a stand-in `systemctl` says the simulator is active, a
stand-in `csrouter` prints counters and status as csrouter does, and the run folder holds a
score log. With fewer `--hosts` than runs, runs share hosts. Every figure comes from one
process and one run of this script:

- `connect per beat`: the path before kept connections (a new executor per run, runs one
  after the other), 30 runs: the reference the new beat is compared with;
- `cold` (the first beat: every connection made) and `steady` (median of the next beats,
  connections kept) for 1, 10 and 30 runs;
- 30 runs while one sim takes 6 s to answer (its stand-in `systemctl` sleeps), and while one
  host is frozen (SIGSTOP: its sshd and sessions do not answer at all): the beat ends after
  CLOUDSIM_RUN_PROBE_SECONDS with the other 29 runs answered, the slow one late (its answer
  is applied by a later beat).

Usage: python -m bench.supervision [--runs 30] [--hosts 30] [--beats 5]
"""

from __future__ import annotations

import argparse
import os
import shlex
import shutil
import signal
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

from sqlalchemy import select

from cloudsim.app import create_app
from cloudsim.competition.jobs import machines
from cloudsim.competition.supervision import BeatReport, Supervisor, ask_router, ask_sim
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import Run, RunState, Team
from provisioners.providers.local.driver import LocalNodeDriver
from provisioners.remote.ssh import ConnectionCache
from tests.support.lightweight_runs import SYSTEMCTL, Host, boot_hosts, live_run
from tests.support.servers import bench_redis

PREFIX = "csbeatb"
SLOW_SECONDS = 6
SLOW_SYSTEMCTL = f"#!/bin/sh\nsleep {SLOW_SECONDS}\nexit 0\n"


def main() -> None:
    if os.geteuid() != 0:
        raise SystemExit("bench/supervision.py needs root (local hosts are namespaces)")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=30, help="most live runs measured")
    parser.add_argument("--hosts", type=int, default=30, help="local hosts (runs share them)")
    parser.add_argument("--beats", type=int, default=5, help="steady beats per figure")
    args = parser.parse_args()
    print(f"load before: {_uptime()}")
    scratch = Path(tempfile.mkdtemp(prefix=f"{PREFIX}-"))
    redis = bench_redis(scratch)
    driver = LocalNodeDriver(
        state_dir=str(scratch / "state"),
        prefix=PREFIX,
        subnet_pool="10.232.0.0/16",
        public_cidr="198.18.32.0/24",
    )
    config = Config.from_env(
        {
            "CLOUDSIM_INSTANCE_DIR": str(scratch / "instance"),
            "CLOUDSIM_REDIS_URL": redis.url(),
            "CLOUDSIM_LOG_LEVEL": "WARNING",
        }
    )
    app = create_app(config)
    try:
        started = time.monotonic()
        names = [f"h{index}" for index in range(min(args.hosts, args.runs))]
        hosts = boot_hosts(driver, f"{PREFIX}-lan", names)
        print(f"{len(hosts)} minimal hosts up in {time.monotonic() - started:.1f} s")
        with app.app_context():
            db.create_all()
            _bench(config, hosts, args.runs, args.beats)
    finally:
        for node in driver.list_nodes():
            driver.destroy_node(node)
        for network in driver.ex_list_networks():
            driver.ex_destroy_network(network)
        redis.stop()
        shutil.rmtree(scratch)
    print(f"load after: {_uptime()}")


def _bench(config: Config, hosts: list[Host], most: int, beats: int) -> None:
    sizes = sorted({1, min(10, most), most})
    figures: dict[str, float] = {}
    for size in sizes:
        _live_runs(hosts, size)
        if size == most:
            figures["old"] = statistics.median([_old_beat(config) for _ in range(beats)])
        cold, steady, report = _new_beats(config, beats)
        figures[f"cold {size}"], figures[f"steady {size}"] = cold, steady
        print(
            f"{size:3d} runs ({report.asked} machines): first beat {cold * 1000:7.1f} ms,"
            f" steady beat {steady * 1000:7.1f} ms (median of {beats});"
            f" {report.connections}"
        )
    old = figures["old"]
    print(f"{most:3d} runs, connect per beat, one run after another: {old * 1000:7.1f} ms")
    slow, caught_up = _slow_beat(config, hosts[0])
    print(
        f"{most:3d} runs, one sim answering after {SLOW_SECONDS} s:"
        f" beat {slow.seconds * 1000:7.1f} ms,"
        f" {slow.answered} machines answered on time, late runs {slow.late};"
        f" its answer applied by a beat {caught_up:.1f} s later"
    )
    frozen = _frozen_beat(config, hosts[0])
    print(
        f"{most:3d} runs, one host frozen: beat {frozen.seconds * 1000:7.1f} ms"
        f" (CLOUDSIM_RUN_PROBE_SECONDS={config.run_probe_seconds}),"
        f" {frozen.answered} machines answered on time, late runs {frozen.late}"
    )
    one, many, cold = figures["steady 1"], figures[f"steady {most}"], figures[f"cold {most}"]
    print("ratios:")
    print(f"  steady beat, {most} runs / 1 run:                 {many / one:6.2f}")
    print(f"  connect per beat / kept connections, {most} runs: {old / many:6.2f}")
    print(f"  first beat / steady beat, {most} runs:            {cold / many:6.2f}")
    print(f"  one slow sim / steady beat, {most} runs:          {slow.seconds / many:6.2f}")
    print(f"  one host frozen / steady beat, {most} runs:       {frozen.seconds / many:6.2f}")


def _slow_beat(config: Config, slow: Host) -> tuple[BeatReport, float]:
    """Time a beat while one sim takes SLOW_SECONDS to answer, and when its answer lands."""
    cache = ConnectionCache()
    supervisor = Supervisor(cache)
    try:
        supervisor.beat(config)
        db.session.commit()
        slow.run(f"printf '%s' {shlex.quote(SLOW_SYSTEMCTL)} > /usr/local/bin/systemctl")
        try:
            report = supervisor.beat(config)
            db.session.commit()
            started = time.monotonic()
            while True:
                time.sleep(1.0)  # the beat's period, shortened
                later = supervisor.beat(config)
                db.session.commit()
                if not later.late:
                    return report, time.monotonic() - started
        finally:
            slow.run(f"printf '%s' {shlex.quote(SYSTEMCTL)} > /usr/local/bin/systemctl")
    finally:
        supervisor.close()
        cache.clear()


def _frozen_beat(config: Config, frozen: Host) -> BeatReport:
    """Time a beat while one host answers nothing (connections were made before)."""
    cache = ConnectionCache()
    supervisor = Supervisor(cache)
    try:
        supervisor.beat(config)
        db.session.commit()
        frozen.signal(signal.SIGSTOP)
        try:
            report = supervisor.beat(config)
            db.session.commit()
        finally:
            frozen.signal(signal.SIGCONT)
        return report
    finally:
        supervisor.close()
        cache.clear()


def _live_runs(hosts: list[Host], count: int) -> None:
    """Leave exactly `count` running runs, each on its own constellation (sim and router)."""
    for run in db.session.scalars(select(Run)):
        db.session.delete(run)
    db.session.commit()
    for index in range(count):
        team = Team(name=f"Team {count}-{index}")
        db.session.add(team)
        db.session.flush()
        live_run(team.id, f"c{count}-{index}", hosts[index % len(hosts)], ("sim", "router"))


def _new_beats(config: Config, beats: int) -> tuple[float, float, BeatReport]:
    cache = ConnectionCache()
    supervisor = Supervisor(cache)
    try:
        first = supervisor.beat(config)
        db.session.commit()
        steady = []
        for _ in range(beats):
            report = supervisor.beat(config)
            db.session.commit()
            if report.late or report.failed:
                raise SystemExit(f"a beat did not hear from every machine: {report}")
            steady.append(report.seconds)
        return first.seconds, statistics.median(steady), report
    finally:
        supervisor.close()
        cache.clear()


def _old_beat(config: Config) -> float:
    """Time the path before kept connections: per run a new executor, sim then router."""
    started = time.monotonic()
    for run in db.session.scalars(select(Run).where(Run.state == RunState.RUNNING)):
        with machines(run, config) as reach:
            ask_sim(reach.executor, reach.sim, run.id)
            assert reach.router is not None
            ask_router(reach.executor, reach.router)
    db.session.commit()
    return time.monotonic() - started


def _uptime() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()


if __name__ == "__main__":
    main()
