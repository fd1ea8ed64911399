"""Benchmark GET /metrics: what a Prometheus scrape costs as a season grows.

The collector reads everything from the database at scrape time. A season of 30 teams (a
live run, a constellation of 4 machines and a team instance each) is measured with 1,000 and
then 30,000 finished jobs (the job-duration histogram reads every finished job), against
GET /healthz in the same run as the reference. Figures: median of 20 scrapes, SQL statements
per scrape, and the ratio to the reference.

Usage: python -m bench.metrics
"""

from __future__ import annotations

import shutil
import statistics
import tempfile
import time
from datetime import timedelta
from pathlib import Path

from flask import Flask
from sqlalchemy import event, insert

from cloudsim.app import create_app
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import Job, JobState, utcnow
from tests.monitoring.support import measurable_season
from tests.support.servers import bench_redis

TEAMS = 30
ROUNDS = 20


def _median_ms(app: Flask, path: str) -> tuple[float, int]:
    """Return the median wall time of GET path, in ms, and the SQL statements of one call."""
    client = app.test_client()
    statements: list[str] = []

    def count(*args: object) -> None:
        statements.append(str(args[2]))

    times = []
    for round_ in range(ROUNDS):
        if round_ == 0:
            event.listen(db.engine, "before_cursor_execute", count)
        started = time.perf_counter()
        assert client.get(path).status_code == 200
        times.append(1000 * (time.perf_counter() - started))
        if round_ == 0:
            event.remove(db.engine, "before_cursor_execute", count)
    return statistics.median(times), len(statements)


def _add_jobs(count: int) -> None:
    now = utcnow()
    rows = [
        dict(
            id=f"bench-{now.timestamp()}-{i}",
            kind=("launch", "run.start", "run.stop", "diagnostics")[i % 4],
            state=JobState.SUCCEEDED,
            params={},
            stage="",
            progress=100,
            log="",
            attempts=1,
            created_at=now - timedelta(hours=2),
            started_at=now - timedelta(hours=2),
            finished_at=now - timedelta(hours=2) + timedelta(seconds=i % 600),
            updated_at=now,
        )
        for i in range(count)
    ]
    db.session.execute(insert(Job), rows)
    db.session.commit()


def main() -> None:
    folder = Path(tempfile.mkdtemp(prefix="bench-metrics-"))
    redis = bench_redis(folder)
    try:
        config = Config.from_env(
            {"CLOUDSIM_INSTANCE_DIR": str(folder / "instance"), "CLOUDSIM_REDIS_URL": redis.url()}
        )
        app = create_app(config)
        with app.app_context():
            db.create_all()
            for team in range(TEAMS):
                measurable_season(f"Bench team {team}", suffix=f"-{team}")
            print(f"GET /metrics on SQLite, {TEAMS} teams with a live run, 2 machines each")
            print(f"{'finished jobs':>14} {'median ms':>10} {'SQL':>4} {'x /healthz':>11}")
            total = 0
            for jobs in (1_000, 30_000):
                _add_jobs(jobs - total)
                total = jobs
                reference, _ = _median_ms(app, "/healthz")
                scrape, statements = _median_ms(app, "/metrics")
                print(f"{jobs:>14,} {scrape:>10.1f} {statements:>4} {scrape / reference:>11.1f}")
            print(f"reference GET /healthz: {reference:.2f} ms")
            db.session.remove()
            db.engine.dispose()
    finally:
        redis.stop()
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
