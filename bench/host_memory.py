"""Measure the memory one local host of each role takes, idle once its constellation is ready.

Launches one constellation of each kind (cloudsim, vrc, simple) through CloudSim on the local
provider (a private Redis, an in-process worker), waits until it is ready and has settled,
and measures each host: the PSS of every process in it (its launcher included) plus what its
overlay's upper layer holds on the hosts' tmpfs (files a host writes are memory here). Prints
each role's figure and its ratio to the figure the provider counts now; with --write, stores
the largest figure seen per role in provisioners/providers/local/host_memory.json, which the
local provider's capacity reads (times its margin). A `sim` host counts its idle figure plus
the peak of a run's simulator (`drcsim serve` on a VRC world, measured here too): capacity
must hold the runs, not only the idle machines.

Needs root. Usage: python -m bench.host_memory [--kinds cloudsim,vrc,simple] [--settle 20]
[--write] [--simulator-only --kinds ""]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from datetime import UTC, datetime
from importlib import resources
from pathlib import Path

from celery.contrib.testing.worker import start_worker
from drcsim.rundir import serve_argv
from libcloud.compute.base import Node

from bench.local_hosts import host_pss_kib
from bench.provision import wait
from cloudsim.app import create_app
from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations import service
from cloudsim.providers.service import open_provider
from provisioners.providers.local import host_memory, processes
from tests.support.servers import bench_redis


def upper_kib(hosts_dir: Path, node: Node) -> int:
    """Return what the host's overlay upper layer holds (on the hosts' tmpfs), in KiB."""
    upper = hosts_dir / node.name / "upper"
    out = subprocess.run(
        ["du", "-s", "-k", "-x", str(upper)], capture_output=True, text=True, check=False
    ).stdout
    return int(out.split()[0]) if out.strip() else 0


def measure(kinds: list[str], settle: float) -> dict[str, list[float]]:
    """Launch each kind, measure each host once ready and settled; return MiB per role."""
    instance = Path(tempfile.mkdtemp(prefix="cloudsim-bench-memory-"))
    redis = bench_redis(instance)
    env = {
        "CLOUDSIM_INSTANCE_DIR": str(instance),
        "CLOUDSIM_REDIS_URL": redis.url(),
        "CLOUDSIM_LOCAL_PREFIX": "csmem",
        "CLOUDSIM_LOCAL_SUBNET_POOL": "10.239.0.0/16",
        "CLOUDSIM_LOCAL_PUBLIC_CIDR": "198.18.39.0/24",
        "CLOUDSIM_LOG_LEVEL": "WARNING",
        # a loaded machine must not fail the launch (a slow self-test, a quiet image build
        # outlasting the watchdog): the bench measures memory, not speed
        "CLOUDSIM_SIM_MIN_RTF": "0.05",
        "CLOUDSIM_JOB_STALL_SECONDS": "3600",
    }
    app = create_app(Config.from_env(env))
    figures: dict[str, list[float]] = defaultdict(list)
    try:
        with app.app_context():
            db.create_all()
            driver = open_provider("local", app.config["CLOUDSIM"]).driver
            with start_worker(
                app.extensions["celery"], pool="threads", concurrency=2,
                perform_ping_check=False, loglevel="WARNING", shutdown_timeout=60,
            ):  # fmt: skip
                for kind in kinds:
                    name = f"mem-{kind}"
                    _, job = service.launch(SYSTEM, name=name, kind=kind, provider="local")
                    seconds = wait([job.id])
                    time.sleep(settle)  # late boot work (journald flush, first requests)
                    for node in open_provider("local", app.config["CLOUDSIM"]).nodes(name):
                        role = node.extra["tags"].get("cloudsim:role", "")
                        kib = host_pss_kib(node) + upper_kib(driver.hosts_dir, node)  # type: ignore[attr-defined]
                        figures[role].append(kib / 1024)
                        print(f"  {kind:9s} {node.name:24s} {role:9s} {kib / 1024:7.1f} MiB")
                    print(f"  {kind} ready in {seconds:.0f} s")
                    wait([service.terminate(SYSTEM, name).id])
    finally:
        with app.app_context():
            open_provider("local", app.config["CLOUDSIM"]).driver.ex_sweep()  # type: ignore[attr-defined]
        redis.stop()
        shutil.rmtree(instance, ignore_errors=True)
    return figures


def simulator_run_mib(seconds: float = 20.0) -> float:
    """Return the peak PSS (MiB) of a run's simulator (what `sim` takes on top while a run
    goes): `drcsim serve` on a VRC world, sampled twice a second for `seconds`."""
    drcsim = Path(sys.executable).with_name("drcsim")
    with tempfile.TemporaryDirectory(prefix="cloudsim-bench-sim-") as logs:
        argv = serve_argv(
            str(drcsim), "vrc_task_2", 1, bind="127.0.0.1", allow=["127.0.0.0/8"],
            log_dir=logs, time_limit_s=seconds + 30,
        )  # fmt: skip
        process = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        peak = 0
        try:
            deadline = time.monotonic() + seconds
            while time.monotonic() < deadline and process.poll() is None:
                peak = max(peak, processes.proportional_memory_kib(process.pid))
                time.sleep(0.5)
        finally:
            process.terminate()
            process.wait(30)
    return peak / 1024


def write(figures: dict[str, list[float]]) -> Path:
    """Store the largest figure per role (rounded up to MiB) as the provider's package data."""
    path = Path(str(resources.files(host_memory.__package__).joinpath(host_memory.FIGURES)))
    stored = json.loads(path.read_text())
    for role, values in figures.items():
        if role:
            stored["roles_mib"][role] = int(max(values)) + 1
    stored["default_mib"] = max(stored["roles_mib"].values())
    stored["measured"] = (
        f"{datetime.now(UTC):%Y-%m-%d} by bench/host_memory.py on {os.cpu_count()} cores, "
        f"{os.sysconf('SC_PHYS_PAGES') * os.sysconf('SC_PAGE_SIZE') // 2**30} GiB"
    )
    path.write_text(json.dumps(stored, indent=2) + "\n")
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kinds", default="cloudsim,vrc,simple")
    parser.add_argument("--settle", type=float, default=20.0)
    parser.add_argument("--write", action="store_true")
    parser.add_argument(
        "--simulator-only", action="store_true", help="measure only a run's simulator (sim)"
    )
    args = parser.parse_args()
    if os.geteuid() != 0:
        raise SystemExit("bench/host_memory.py needs root (the local provider makes namespaces)")
    counted = host_memory.measured()
    print("memory per local host, idle once ready (PSS of its processes + its tmpfs layer)")
    figures = measure(args.kinds.split(","), args.settle) if args.kinds else defaultdict(list)
    if "sim" in figures or args.simulator_only:
        # a sim host idle takes little; while a run goes its simulator takes the most
        running = simulator_run_mib()
        print(f"  a run's simulator (drcsim serve, vrc_task_2) peak {running:7.1f} MiB")
        idle = max(figures["sim"], default=float(counted.roles_mib.get("sim", 0)) / 1.25)
        figures["sim"] = [idle + running]
    print(f"  {'role':9s} {'measured':>9s} {'counted':>9s}  ratio counted/measured")
    for role, values in sorted(figures.items()):
        peak = max(values)
        now = counted.of(role)
        print(f"  {role:9s} {peak:7.1f} M {now:7d} M  {now / peak:5.2f}")
    if args.write:
        print(f"wrote {write(figures)}")


if __name__ == "__main__":
    main()
