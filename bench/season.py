"""Benchmark a launch storm: N vrc constellations launched at once on the local provider.

Needs root. Seeds bench/web.py's season (30 teams, 300 users, 1,000 jobs), starts the
production stack (`cloudsim up`: gunicorn, Celery worker and beat, private Redis) on a fresh
instance, builds the simulator's wheelhouse first (timed on its own: an installation builds
it once), then POSTs N launches at once to the API and, while they run, drives the dashboards
with bench/web.py's clients. Reports the time until every launch ended, failures, peak memory,
the controller's CPU and the dashboards' p95; terminates everything, sweeps the local
provider, and exits non-zero if a launch failed or anything was left behind.
Usage: python -m bench.season [--count 30] [--clients 6] [--concurrency 8]
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import requests

from bench.web import bench_env, drive, seed, stack
from cloudsim.app import create_app
from cloudsim.config import Config
from cloudsim.providers.service import open_provider
from constellations.plans.software import build_wheelhouse, distribution_source

FINAL = {"ready", "error"}
CLOCK_TICKS = os.sysconf("SC_CLK_TCK")


def percentiles(values: list[float]) -> tuple[float, float]:
    """Return the median and the 95th percentile of values."""
    ordered = sorted(values)
    return statistics.median(ordered), ordered[int(0.95 * (len(ordered) - 1))]


def stack_pid() -> int:
    """Return the PID of the `cloudsim up` this process started (bench.web.stack's child)."""
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            cmdline = (stat.parent / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if int(fields[1]) == os.getpid() and cmdline[1:4] == [b"-m", b"cloudsim.cli", b"up"]:
            return int(stat.parent.name)
    raise SystemExit("cannot find the cloudsim up this benchmark started")


def used_memory() -> int:
    """Return the machine's memory in use (total minus available), bytes."""
    fields = dict(line.split(":", 1) for line in Path("/proc/meminfo").read_text().splitlines())
    kib = {name: int(value.split()[0]) for name, value in fields.items()}
    return (kib["MemTotal"] - kib["MemAvailable"]) * 1024


def hosts_memory(prefix: str, hosts_dir: Path) -> tuple[int, int]:
    """Return the hosts' files (their tmpfs) and their processes' resident memory, bytes.

    A host's processes are those in its own cgroup (named after the prefix, see cgroups.py);
    resident memory counts pages shared between hosts once per process (an upper bound).
    """
    try:
        usage = os.statvfs(hosts_dir)
        files = (usage.f_blocks - usage.f_bfree) * usage.f_frsize if hosts_dir.is_mount() else 0
    except OSError:
        files = 0
    resident = 0
    page = os.sysconf("SC_PAGE_SIZE")
    for cgroup in Path("/proc").glob("[0-9]*/cgroup"):
        try:
            if f"::/{prefix}-" not in cgroup.read_text():
                continue
            resident += int((cgroup.parent / "statm").read_text().split()[1]) * page
        except OSError:
            continue
    return files, resident


def process_tree_cpu(root: int, seen: dict[int, float]) -> float:
    """Return the CPU seconds of root's process tree (children's reaped time included).

    seen keeps each process's largest figure, so processes that ended still count.
    """
    parents: dict[int, int] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:
            continue
        fields = text.rsplit(")", 1)[1].split()
        pid = int(stat.parent.name)
        parents[pid] = int(fields[1])
        cpu = sum(int(value) for value in fields[11:15]) / CLOCK_TICKS
        seen[pid] = max(seen.get(pid, 0.0), cpu) if pid != root else cpu
    tree = {root}
    grew = True
    while grew:
        grew = False
        for pid, parent in parents.items():
            if parent in tree and pid not in tree:
                tree.add(pid)
                grew = True
    # a process in the tree that ended was reaped by its parent: its time is in the parent's
    return sum(cpu for pid, cpu in seen.items() if pid in tree)


def launch_all(base: str, headers: dict[str, str], names: list[str]) -> list[int]:
    """POST every launch at once; return the constellations' ids."""

    def launch(index_name: tuple[int, str]) -> int:
        index, name = index_name
        body: dict[str, Any] = {"name": name, "kind": "vrc", "team_id": index % 30 + 1}
        answer = requests.post(
            f"{base}/api/v1/constellations", json=body, headers=headers, timeout=120
        )
        if answer.status_code != 202:
            raise SystemExit(f"launch {name}: {answer.status_code} {answer.text[:300]}")
        return int(answer.json()["constellation"]["id"])

    with ThreadPoolExecutor(max_workers=len(names)) as pool:
        return list(pool.map(launch, enumerate(names)))


def states(base: str, headers: dict[str, str], ids: list[int]) -> dict[int, dict[str, Any]]:
    """Return the constellations' rows by id."""
    rows = requests.get(
        f"{base}/api/v1/constellations?page_size=500", headers=headers, timeout=60
    ).json()
    return {row["id"]: row for row in rows if row["id"] in ids}


def wait_for(
    base: str, headers: dict[str, str], ids: list[int], done: set[str], timeout: float
) -> dict[int, dict[str, Any]]:
    """Poll until every constellation is in one of done; return the rows."""
    deadline = time.monotonic() + timeout
    while True:
        rows = states(base, headers, ids)
        if len(rows) == len(ids) and all(row["state"] in done for row in rows.values()):
            return rows
        if time.monotonic() > deadline:
            stuck = {row["name"]: row["state"] for row in rows.values() if row["state"] not in done}
            raise SystemExit(f"still not {'/'.join(sorted(done))} after {timeout:.0f} s: {stuck}")
        time.sleep(2)


@dataclass
class Figures:
    """What the storm measured."""

    storm: float = 0.0
    terminate: float = 0.0
    cpu: float = 0.0
    peak: list[int] = field(default_factory=lambda: [0, 0, 0])  # machine, hosts' files, procs
    failed: dict[str, object] = field(default_factory=dict)
    timings: dict[str, list[float]] = field(default_factory=dict)


def storm(
    base: str, headers: dict[str, str], args: argparse.Namespace, prefix: str, hosts_dir: Path
) -> Figures:
    """Launch the storm while sampling and driving the dashboards; terminate it; measure."""
    figures = Figures()
    root = stack_pid()
    cpu_seen: dict[int, float] = {}
    memory_before = used_memory()
    over = threading.Event()

    def sample() -> None:
        while not over.wait(1):
            files, resident = hosts_memory(prefix, hosts_dir)
            peak = figures.peak
            figures.peak = [
                max(peak[0], used_memory() - memory_before),
                max(peak[1], files),
                max(peak[2], resident),
            ]
            process_tree_cpu(root, cpu_seen)

    def dashboards() -> None:
        while not over.is_set():
            for name, values in drive(base, headers, args.clients, 1).items():
                figures.timings.setdefault(name, []).extend(values)

    room = requests.get(f"{base}/api/v1/constellations/capacity", headers=headers, timeout=60)
    print(f"before the storm: {room.json()}")
    cpu_before = process_tree_cpu(root, cpu_seen)
    threads = [threading.Thread(target=sample), threading.Thread(target=dashboards)]
    for thread in threads:
        thread.start()
    started = time.perf_counter()
    try:
        ids = launch_all(base, headers, [f"storm-{n:02d}" for n in range(args.count)])
        rows = wait_for(base, headers, ids, FINAL, args.timeout)
        figures.storm = time.perf_counter() - started
        figures.cpu = process_tree_cpu(root, cpu_seen) - cpu_before
    finally:
        over.set()
        for thread in threads:
            thread.join()
    figures.failed = {row["name"]: row["error"] for row in rows.values() if row["state"] != "ready"}
    started = time.perf_counter()
    for constellation_id in ids:
        requests.delete(
            f"{base}/api/v1/constellations/{constellation_id}", headers=headers, timeout=60
        ).raise_for_status()
    wait_for(base, headers, ids, {"terminated"}, args.timeout)
    figures.terminate = time.perf_counter() - started
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=30, help="launches at once (default 30)")
    parser.add_argument("--clients", type=int, default=6, help="dashboard clients meanwhile")
    parser.add_argument("--concurrency", type=int, default=8, help="Celery worker processes")
    parser.add_argument("--timeout", type=float, default=1200)
    args = parser.parse_args()
    if os.geteuid() != 0:
        raise SystemExit("bench/season.py needs root (the local provider makes namespaces)")
    instance = Path(tempfile.mkdtemp(prefix="cloudsim-bench-season-"))
    prefix = "csstorm"
    env = bench_env(instance, None) | {
        "CLOUDSIM_WORKER_CONCURRENCY": str(args.concurrency),
        "CLOUDSIM_LOCAL_PREFIX": prefix,
        "CLOUDSIM_LOCAL_SUBNET_POOL": "10.215.0.0/16",
        "CLOUDSIM_LOCAL_PUBLIC_CIDR": "198.18.15.0/24",
        # the dashboards' clients log in again every round: cheap hashes keep that off the CPU
        "CLOUDSIM_ARGON2_TIME_COST": "1",
        "CLOUDSIM_ARGON2_MEMORY_KIB": "1024",
    }
    config = Config.from_env(env)
    hosts_dir = instance / "local-hosts" / prefix / "hosts"
    try:  # the folder goes whatever fails, seeding and the wheelhouse build included
        headers = seed(env)
        started = time.perf_counter()
        build_wheelhouse(
            distribution_source("drcsim"), instance / "wheelhouse", config.machine_python
        )
        wheelhouse = time.perf_counter() - started
        with stack(env, instance) as base:
            figures = storm(base, headers, args, prefix, hosts_dir)
    finally:
        with create_app(config).app_context():
            leaked = open_provider("local", config).driver.ex_sweep()  # type: ignore[attr-defined]
        shutil.rmtree(instance, ignore_errors=True)  # its wheelhouse and logs
    report(args, wheelhouse, figures)
    if leaked:
        print(f"  LEFT BEHIND (swept): {leaked}")
    if figures.failed or leaked:
        raise SystemExit(1)


def report(args: argparse.Namespace, wheelhouse: float, figures: Figures) -> None:
    """Print the storm's figures."""
    load = Path("/proc/loadavg").read_text().split()[:3]
    print(f"launch storm: {args.count} vrc constellations at once on the local provider")
    print(f"  machine: {os.cpu_count()} cores, load {' '.join(load)} at the end")
    print(f"  wheelhouse build (once, cached)        {wheelhouse:7.1f} s")
    print(
        f"  all {args.count} ended (ready or error)       {figures.storm:7.1f} s   (goal <= 300 s)"
    )
    print(f"  per constellation                      {figures.storm / args.count:7.1f} s")
    print(f"  failures                               {len(figures.failed):7d}     (goal 0)")
    for name, error in sorted(figures.failed.items()):
        print(f"    {name}: {str(error)[:300]}")
    print(f"  peak memory in use, added (machine)    {figures.peak[0] / 2**30:7.2f} GiB")
    print(f"  peak hosts' files (tmpfs)              {figures.peak[1] / 2**30:7.2f} GiB")
    print(f"  peak hosts' processes (resident)       {figures.peak[2] / 2**30:7.2f} GiB")
    print(
        f"  controller CPU (web, worker, beat)     {figures.cpu:7.1f} s   "
        f"({figures.cpu / figures.storm:.2f} cores of {os.cpu_count()} on average)"
    )
    print(f"  terminate all                          {figures.terminate:7.1f} s")
    print(f"  dashboards meanwhile ({args.clients} clients):")
    for name, values in sorted(figures.timings.items()):
        p50, p95 = percentiles(values)
        print(
            f"    {name:30} n {len(values):4d}  p50 {p50 * 1000:6.0f} ms  p95 {p95 * 1000:6.0f} ms"
        )


if __name__ == "__main__":
    main()
