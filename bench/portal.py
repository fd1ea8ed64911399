"""Benchmark the portal at season scale: p50/p95 of the leaderboard, figures and exports.

Seeds a season (bench/web.py's: 30 teams x 15 finished runs with stored score logs and
30-minute bandwidth logs) into a fresh instance, starts the production stack with
`cloudsim up` and drives the portal's pages with 20 clients (officers and team users), against
the anonymous login page as the reference measured in the same run. Each step of the run
(seeding the season, then the pages under load) prints its own figures.
Usage: python -m bench.portal [--db sqlite|postgresql|both] [--clients 20] [--rounds 6]
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from flask import Flask
from sqlalchemy import select

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
USER_PAGES = ["/leaderboard", "/leaderboard/standings", "/portal", "/portal/figures"]


@dataclass
class Season:
    """A seeded instance: its environment, folder and how long each step took to fill it."""

    env: dict[str, str]
    instance: Path
    steps: dict[str, float]


def seed_season(season: Season) -> None:
    """Fill the database with the season's rows and stored logs (bench/web.py's seed)."""
    seed(season.env)


# The steps that bring a season into the portal, each timed and reported; a step that sends
# the runs through the team instances' upload instead of writing rows goes here too.
STEPS: list[tuple[str, Callable[[Season], None]]] = [("seed 450 runs as rows", seed_season)]


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
    """Bring a season in step by step, load the portal's pages, print the tables."""
    instance = Path(tempfile.mkdtemp(prefix="cloudsim-bench-portal-"))
    season = Season(bench_env(instance, database_url), instance, {})
    for name, step in STEPS:
        started = time.perf_counter()
        step(season)
        season.steps[name] = time.perf_counter() - started
    load = os.getloadavg()
    print(f"\nportal benchmark on {label}; load average {load[0]:.1f} {load[1]:.1f} {load[2]:.1f}")
    for name, seconds in season.steps.items():
        print(f"{name}: {seconds:.1f} s")
    clients_of = visitors(season.env, clients)
    app = create_app(Config.from_env(season.env))
    kinds = {v.email.split("@")[0].rstrip("0123456789"): v for v in clients_of}
    with stack(season.env, instance) as base:  # its Redis: logging in counts attempts there
        queries = count_queries(app, kinds)
        started = time.perf_counter()
        timings = drive(base, {}, clients, rounds, lambda number: clients_of[number])
        wall = time.perf_counter() - started
        costs = in_process(app, list(kinds.values()))  # once the stack has settled
    report(label, seeded(app), sum(season.steps.values()), timings, queries, wall, clients)
    reference = next(v for k, v in costs.items() if k.startswith("reference"))
    print("in-process, one request at a time (median of 5), against the login page:")
    for name, ms in sorted(costs.items()):
        print(f"  {name:44} {ms:7.1f} ms {ms / reference:6.1f}x")


def main() -> None:
    on_each_database(arguments(__doc__ or "", "sqlite", 6).parse_args(), measure)


if __name__ == "__main__":
    main()
