"""Benchmark run verification: runs verified per CPU-hour and the time to verify a 30-minute run.

Records real drcsim runs of vrc_task_2 (a walk, an arm moved, a stand; no sensors, stepped as
fast as the machine goes, logs written as a served run writes them) of two lengths, SHORT and
LONG simulated seconds: that recording is the reference, the simulator's plain run of the same
length. Each run is stored as a finished run of a CloudSim (SQLite, local log store) and
verified by the real job (`run.verify`, run in this process: logs copied and checked, `drcsim
replay` in its own process, comparison). Prints per length the wall and CPU seconds of both and
their ratio; then, from the two lengths (time = fixed + per simulated second), the figures for
a 30-minute run, EXTRAPOLATED unless --full measures one (about an hour on one core).
Usage: python -m bench.verification [--short 10] [--long 40] [--full]
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from drcsim.worlds import shipped_document
from sqlalchemy import select

from cloudsim.app import create_app
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.jobs.service import run_here
from cloudsim.models import Job, Team, Verification
from cloudsim.verification import service
from tests.competition.support import open_task
from tests.support.servers import bench_redis
from tests.verification.support import TIMEOUT_S, WORLD_NAME, master_run, simulate

THIRTY_MINUTES = 1800.0


@dataclass(frozen=True)
class Cost:
    """Wall and CPU seconds of one piece of work (its child processes' CPU included)."""

    wall: float
    cpu: float


def _cpu() -> float:
    own, children = (
        resource.getrusage(resource.RUSAGE_SELF),
        resource.getrusage(resource.RUSAGE_CHILDREN),
    )
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _timed(work: object) -> tuple[object, Cost]:
    wall, cpu = time.perf_counter(), _cpu()
    result = work()  # type: ignore[operator]
    return result, Cost(time.perf_counter() - wall, _cpu() - cpu)


def _fit(short: tuple[float, float], long: tuple[float, float], at: float) -> float:
    """Return the straight line through (seconds, cost) of both lengths, at `at` seconds."""
    (s1, c1), (s2, c2) = short, long
    per_second = (c2 - c1) / (s2 - s1)
    return c1 + per_second * (at - s1)


def _measure(seconds: float, scratch: Path, team_id: int, verified: list[int]) -> tuple[Cost, Cost]:
    """Record a run of `seconds` (the plain run) and verify it; return both costs."""
    folder = scratch / f"run-{seconds:g}"
    folder.mkdir()
    world = shipped_document(WORLD_NAME)
    timeout = max(TIMEOUT_S, int(seconds) + 10)
    logs, plain = _timed(lambda: simulate(folder, world, seconds))
    task = open_task(team_id, timeout_s=timeout, name=f"Walking {seconds:g}")
    run = master_run(task, logs, scratch / "stored")  # type: ignore[arg-type]
    assert service.request_verification(run.id)
    db.session.commit()
    job = db.session.scalar(select(Job).where(Job.kind == service.VERIFY, Job.target_id == run.id))
    assert job is not None
    _, verification = _timed(lambda: run_here(job.id))
    db.session.expire_all()
    if run.verification is not Verification.VERIFIED:
        raise SystemExit(f"run of {seconds:g} s not verified: {run.verification_reason}")
    verified.append(run.id)
    return plain, verification


def _row(label: str, plain: Cost, check: Cost) -> str:
    return (
        f"{label:>22} | plain run {plain.wall:7.2f} s wall {plain.cpu:7.2f} s CPU | "
        f"verification {check.wall:7.2f} s wall {check.cpu:7.2f} s CPU | "
        f"ratio {check.wall / plain.wall:5.2f} wall {check.cpu / plain.cpu:5.2f} CPU"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--short", type=float, default=10.0, help="simulated seconds")
    parser.add_argument("--long", type=float, default=40.0, help="simulated seconds")
    parser.add_argument("--full", action="store_true", help="also measure a 30-minute run")
    arguments = parser.parse_args()
    instance = Path(tempfile.mkdtemp(prefix="cloudsim-bench-verify-"))
    redis = bench_redis(instance)
    env = {
        "CLOUDSIM_INSTANCE_DIR": str(instance / "instance"),
        "CLOUDSIM_REDIS_URL": redis.url(),
        "CLOUDSIM_LOG_LEVEL": "WARNING",
    }
    app = create_app(Config.from_env(env))
    try:
        with app.app_context():
            db.create_all()
            team = Team(name="Bench")
            db.session.add(team)
            db.session.commit()
            print(f"load before: {os.getloadavg()[0]:.2f} (1 min), {os.cpu_count()} CPUs")
            scratch = instance / "runs"
            scratch.mkdir()
            lengths = [arguments.short, arguments.long] + (
                [THIRTY_MINUTES] if arguments.full else []
            )
            costs: dict[float, tuple[Cost, Cost]] = {}
            verified: list[int] = []
            for seconds in lengths:
                costs[seconds] = _measure(seconds, scratch, team.id, verified)
                print(_row(f"{seconds:g} simulated s", *costs[seconds]))
            if THIRTY_MINUTES in costs:
                plain, check = costs[THIRTY_MINUTES]
                how = "measured"
            else:
                short, long = costs[arguments.short], costs[arguments.long]

                def at(pick: int, field: str) -> float:
                    return _fit(
                        (arguments.short, getattr(short[pick], field)),
                        (arguments.long, getattr(long[pick], field)),
                        THIRTY_MINUTES,
                    )

                plain = Cost(at(0, "wall"), at(0, "cpu"))
                check = Cost(at(1, "wall"), at(1, "cpu"))
                how = (
                    f"EXTRAPOLATED from the {arguments.short:g} s and {arguments.long:g} s runs "
                    "(cost = fixed + per simulated second)"
                )
            print(_row("30-minute run", plain, check) + f"  ({how})")
            print(
                f"time to verify a 30-minute run: {check.wall / 60:.1f} min wall "
                f"({check.cpu / 60:.1f} CPU min); runs verified per CPU-hour: "
                f"{3600 / check.cpu:.2f} (30-minute runs), "
                f"{3600 / costs[arguments.short][1].cpu:.1f} ({arguments.short:g} s runs)"
            )
            print(f"load after: {os.getloadavg()[0]:.2f} (1 min); runs verified: {verified}")
            db.session.remove()
    finally:
        redis.stop()
        shutil.rmtree(instance, ignore_errors=True)


if __name__ == "__main__":
    main()
