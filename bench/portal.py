"""Benchmark the portal at season scale: p50/p95 of the leaderboard, figures and exports.

Seeds a season's teams, people and machines (bench/web.py's seed) into a fresh instance,
starts the production stack with `cloudsim up`, uploads its 450 runs (30 teams x 15, a score
log and a 30-minute bandwidth log each) through the portal's ingest API from 30 team
instances at once (timed), then drives the portal's pages with 20 clients (officers and team
users), against the anonymous login page as the reference measured in the same run.
Usage: python -m bench.portal [--db sqlite|postgresql|both] [--clients 20] [--rounds 6]
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

from flask import Flask
from sqlalchemy import select

from bench.portal_ingest import prepare, upload
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


def measure(label: str, database_url: str | None, clients: int, rounds: int) -> None:
    """Seed a season's people, upload its runs as team instances do, load the portal's pages."""
    instance = Path(tempfile.mkdtemp(prefix="cloudsim-bench-portal-"))
    # the instances are stand-ins: the beat's health poll must not call them meanwhile
    env = dict(bench_env(instance, database_url), CLOUDSIM_INSTANCE_POLL_SECONDS="86400")
    started = time.perf_counter()
    seed(env, runs=0)  # teams, people, machines, jobs: the runs arrive through the portal
    seeding = time.perf_counter() - started
    app = create_app(Config.from_env(env))
    uploaders = prepare(app, RUNS_PER_TEAM)
    with stack(env, instance) as base:  # its Redis: logging in counts attempts there
        ingest = upload(base, uploaders)
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
    reference = next(v for k, v in costs.items() if k.startswith("reference"))
    print("in-process, one request at a time (median of 5), against the login page:")
    for name, ms in sorted(costs.items()):
        print(f"  {name:44} {ms:7.1f} ms {ms / reference:6.1f}x")


def main() -> None:
    on_each_database(arguments(__doc__ or "", "sqlite", 6).parse_args(), measure)


if __name__ == "__main__":
    main()
