"""Benchmark the portal at season scale: p50/p95 of the leaderboard, figures and exports.

Seeds a season's teams, people and machines (bench/web.py's seed) into a fresh instance,
starts the production stack with `cloudsim up`, uploads its 450 runs (30 teams x 15, a score
log and a 30-minute bandwidth log each) through the portal's ingest API from 30 team
instances at once (timed), then a sample of runs with a simulator state log of a real run's
size (175 MB for 30 minutes, generated; one run at a time, in 8 MiB pieces), against a local
copy and SHA-256 of the same bytes, then drives the portal's pages with 20 clients (officers
and team users), against the anonymous login page as the reference measured in the same run.
Every file it made is removed at the end.
Usage: python -m bench.portal [--db sqlite|postgresql|both] [--clients 20] [--rounds 6]
       [--state-logs 3] [--state-minutes 30]
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from flask import Flask
from sqlalchemy import select

from bench.portal_ingest import prepare, upload
from bench.portal_logs import StateLog, reference, state_log, upload_large
from bench.web import (
    Visitor,
    arguments,
    bench_env,
    count_queries,
    drive,
    on_each_database,
    report,
    seed,
    seeded,
    stack,
    visits,
)
from cloudsim.app import create_app
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import Run, Team, User

OFFICER_PAGES = [
    "/leaderboard",
    "/leaderboard/standings",
    "/portal",
    "/portal/figures",
    "/portal/figures/bits-banked.csv",
    "/portal/figures/uplink-score.csv",
    "/portal/results.csv",
    "/portal/results.json",
]
RUNS_PER_TEAM = 15
USER_PAGES = ["/leaderboard", "/leaderboard/standings", "/portal", "/portal/figures"]


def visitors(env: dict[str, str], clients: int) -> list[Visitor]:
    """Return the clients: every third an officer, the others members of different teams."""
    app = create_app(Config.from_env(env))
    with app.app_context():
        teams = list(db.session.scalars(select(Team).order_by(Team.id)))
        found = []
        for number in range(clients):
            if number % 3 == 0:
                found.append(
                    Visitor(
                        f"officer{(number // 3) % 3}@example.org",
                        [(f"officer {p}", p) for p in OFFICER_PAGES],
                    )
                )
                continue
            team = teams[number % len(teams)]
            member = db.session.scalar(select(User).where(User.team_id == team.id).limit(1))
            run = db.session.scalar(select(Run.id).where(Run.team_id == team.id).limit(1))
            assert member is not None and run is not None
            pages = [*USER_PAGES, f"/runs/{run}/bandwidth.csv"]
            found.append(
                Visitor(member.email, [(f"user {p.replace(str(run), '{id}')}", p) for p in pages])
            )
        return found


def in_process(app: Flask, visitors: list[Visitor], repeat: int = 5) -> dict[str, float]:
    """Return each request's median milliseconds through Flask's test client (no HTTP, no
    other client): what the page itself costs, whatever the machine's load."""
    costs: dict[str, float] = {}
    for name, url, http, headers in visits(app, visitors):
        times = []
        for _ in range(repeat):
            started = time.perf_counter()
            assert http.get(url, headers=headers).status_code == 200, url
            times.append(time.perf_counter() - started)
        costs[name] = 1000 * statistics.median(times)
    return costs


def measure(args: argparse.Namespace, label: str, database_url: str | None) -> None:
    """Seed a season's people, upload its runs as team instances do, load the portal's pages."""
    instance = Path(tempfile.mkdtemp(prefix="cloudsim-bench-portal-"))
    try:
        with state_log(args.state_minutes) as log:
            _measure(args, label, database_url, instance, log)
    finally:
        shutil.rmtree(instance)  # the stored logs with it (a state log is 175 MB)


def _measure(
    args: argparse.Namespace, label: str, database_url: str | None, instance: Path, log: StateLog
) -> None:
    clients, rounds = args.clients, args.rounds
    # the instances are stand-ins: the beat's health poll must not call them meanwhile
    env = dict(bench_env(instance, database_url), CLOUDSIM_INSTANCE_POLL_SECONDS="86400")
    started = time.perf_counter()
    seed(env, runs=0)  # teams, people, machines, jobs: the runs arrive through the portal
    seeding = time.perf_counter() - started
    app = create_app(Config.from_env(env))
    uploaders = prepare(app, RUNS_PER_TEAM, large=args.state_logs)
    with stack(env, instance) as base:  # its Redis: logging in counts attempts there
        ingest = upload(base, uploaders)
        copies = [reference(log, instance) for _ in range(2)]
        large = upload_large(base, uploaders, log)
        clients_of = visitors(env, clients)
        kinds = {v.email.split("@")[0].rstrip("0123456789"): v for v in clients_of}
        queries = count_queries(app, kinds)
        started = time.perf_counter()
        timings = drive(base, {}, clients, rounds, lambda number: clients_of[number])
        wall = time.perf_counter() - started
        costs = in_process(app, list(kinds.values()))  # once the stack has settled
    config = app.config["CLOUDSIM"]
    server = f"gunicorn {config.web_workers} workers x {config.web_threads} threads"
    report(label, seeded(app), seeding, timings, queries, wall, clients, server)
    print(
        f"ingest: {ingest['runs']} runs from {ingest['instances']} team instances at once "
        f"(record, {ingest['bytes'] / ingest['runs'] / 1e3:.0f} kB of logs, acknowledgement) "
        f"in {ingest['seconds']:.1f} s: {ingest['runs'] / ingest['seconds']:.1f} runs/s, "
        f"{ingest['bytes'] / ingest['seconds'] / 1e6:.1f} MB/s; per run p50 "
        f"{1000 * ingest['p50']:.0f} ms, p95 {1000 * ingest['p95']:.0f} ms"
    )
    _report_large(large, copies, log)
    reference_ms = next(v for k, v in costs.items() if k.startswith("reference"))
    print("in-process, one request at a time (median of 5), against the login page:")
    for name, ms in sorted(costs.items()):
        print(f"  {name:44} {ms:7.1f} ms {ms / reference_ms:6.1f}x")


def _report_large(large: dict[str, Any], copies: list[dict[str, float]], log: StateLog) -> None:
    """Print the large logs' ingest rate against a copy and a SHA-256 of the same bytes."""
    if not large["runs"]:
        return
    mb = log.size / 1e6
    copy = min(c["copy"] for c in copies)
    hashed = min(c["sha256"] for c in copies)
    rates = sorted(mb / s for s in large["seconds"])
    total = large["runs"] * mb / sum(large["seconds"])
    floor = mb / (copy + hashed)
    print(
        f"large logs: {large['runs']} runs with a {mb:.0f} MB state log (and the same small "
        f"logs), one at a time in 8 MiB pieces: {total:.0f} MB/s "
        f"({rates[0]:.0f}-{rates[-1]:.0f} MB/s a run, {sum(large['seconds']):.1f} s); "
        f"reference on the same bytes: copy {mb / copy:.0f} MB/s, SHA-256 {mb / hashed:.0f} "
        f"MB/s, both {floor:.0f} MB/s; ingest / reference {total / floor:.2f}"
    )


def main() -> None:
    parser = arguments(__doc__ or "", "sqlite", 6)
    parser.add_argument(
        "--state-logs", type=int, default=3, help="runs with a state log (one per team)"
    )
    parser.add_argument("--state-minutes", type=float, default=30.0, help="of simulated time")
    args = parser.parse_args()
    on_each_database(args, lambda label, url, _clients, _rounds: measure(args, label, url))


if __name__ == "__main__":
    main()
