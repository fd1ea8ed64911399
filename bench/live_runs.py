"""Benchmark what a live run's page costs the web worker: one `/runs/ID/status` poll (the page
polls it every second) for a run 30 minutes in, its figures and 1,800 bandwidth samples in
Redis, against the same poll of a finished run (the row alone, no cache) measured in the same
run. No machine is asked: pages read the cache the live reader fills.

Runs without root, in-process (Flask's test client), with a private Redis and SQLite.
Usage: python -m bench.live_runs [--minutes 30] [--polls 200]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import tempfile
import time
from datetime import UTC, datetime, timedelta
from pathlib import Path

from flask import Flask
from flask.testing import FlaskClient

from cloudsim import migrate
from cloudsim.app import create_app
from cloudsim.auth.passwords import hash_password
from cloudsim.competition import live
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import Role, Run, RunState, Task, Team, User, utcnow
from tests.support.servers import bench_redis

PASSWORD = "benchmark password"


def seed(app: Flask, minutes: float) -> tuple[int, int]:
    """Add an officer, a finished run and a running run `minutes` in, with its live cache."""
    with app.app_context():
        team = Team(name="Bench")
        db.session.add(team)
        db.session.flush()
        officer = User(
            email="officer@example.org", role=Role.OFFICER, password_hash=hash_password(PASSWORD)
        )
        now = utcnow()
        tasks = [
            Task(
                team_id=team.id,
                name=f"Bench walk {n}",
                world="vrc_task_2",
                run_config=1,
                window_start=now - timedelta(hours=1),
                window_stop=now + timedelta(hours=1),
                uplink_bits=115_200,
                downlink_bits=59_000_000,
                timeout_s=1800,
            )
            for n in (1, 2)
        ]
        db.session.add_all([officer, *tasks])
        db.session.flush()
        started = now - timedelta(minutes=minutes)
        finished = Run(task_id=tasks[0].id, team_id=team.id, state=RunState.FINISHED)
        running = Run(
            task_id=tasks[1].id,
            team_id=team.id,
            state=RunState.RUNNING,
            started_at=started,
            running_at=started,
        )
        db.session.add_all([finished, running])
        db.session.commit()
        seconds = round(minutes * 60)
        client = live.connection(app.config["CLOUDSIM"])
        at = datetime.now(UTC).isoformat()
        events = [
            {
                "kind": "checkpoint",
                "sim_time": 60.0 * i,
                "wall_time": at,
                "checkpoint": i,
                "points": 1,
                "description": f"gate_{i}",
            }
            for i in range(1, 5)
        ]
        figures = {
            "heard": {"sim": at, "router": at, "fc1": at, "fc2": at},
            "sim": {"sim_time": float(seconds), "rtf": 1.0, "score": 4, "falls": 0},
            "sim_advanced_at": at,
            "events": events,
            "used": {"uplink": 40 * seconds, "downlink": 20_000 * seconds},
            "spent_at": {"uplink": None, "downlink": None},
        }
        client.set(live.KEY.format(running.id), json.dumps(figures))
        samples = [json.dumps([s, 40 * s, 20_000 * s]) for s in range(1, seconds + 1)]
        client.rpush(live.SAMPLES_KEY.format(running.id), *samples)
        return finished.id, running.id


def per_poll_ms(client: FlaskClient, run_id: int, polls: int) -> float:
    """Return the median time of one status poll, in milliseconds."""
    times = []
    for _ in range(polls):
        started = time.perf_counter()
        answer = client.get(f"/runs/{run_id}/status")
        times.append((time.perf_counter() - started) * 1000)
        assert answer.status_code == 200, answer.status_code
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--minutes", type=float, default=30.0)
    parser.add_argument("--polls", type=int, default=200)
    args = parser.parse_args()
    print(f"live run page benchmark (load: {os.getloadavg()[0]:.2f})")
    folder = Path(tempfile.mkdtemp(prefix="cloudsim-bench-live-"))
    redis_server = bench_redis(folder)
    try:
        env = {
            "CLOUDSIM_INSTANCE_DIR": str(folder / "instance"),
            "CLOUDSIM_REDIS_URL": redis_server.url(),
            "CLOUDSIM_LOG_LEVEL": "WARNING",
            "CLOUDSIM_ARGON2_TIME_COST": "1",
            "CLOUDSIM_ARGON2_MEMORY_KIB": "1024",
        }
        app = create_app(Config.from_env(env, testing=True))
        app.config["WTF_CSRF_ENABLED"] = False
        migrate.upgrade(app)
        finished, running = seed(app, args.minutes)
        client = app.test_client()
        login = {"email": "officer@example.org", "password": PASSWORD}
        assert client.post("/login", data=login).status_code == 302
        with app.app_context():
            reference = per_poll_ms(client, finished, args.polls)
            live_poll = per_poll_ms(client, running, args.polls)
            size = len(client.get(f"/runs/{running}/status").data)
        print(
            f"status poll of a finished run (row only): {reference:.2f} ms (reference)\n"
            f"status poll of a running run {args.minutes:g} min in (cache, 4 charts of "
            f"{round(args.minutes * 60)} s): {live_poll:.2f} ms (x{live_poll / reference:.1f}), "
            f"{size / 1000:.0f} kB\n"
            f"one web worker serves about {1000 / live_poll:.0f} open live pages (1 poll/s each)"
        )
    finally:
        redis_server.stop()
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
