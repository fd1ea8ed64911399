"""Benchmark the web app under load: p50/p95 of dashboards and API lists, 20 concurrent clients.

Seeds 30 teams, 120 machines, 300 users and 1,000 jobs into a fresh instance, starts the
production stack with `cloudsim up` (gunicorn, private Redis) on free loopback ports, and
drives it with concurrent clients. Usage: python -m bench.web [--clients 20] [--rounds 15]
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from datetime import timedelta
from pathlib import Path

import requests

from cloudsim import migrate
from cloudsim.app import create_app
from cloudsim.auth.passwords import hash_password
from cloudsim.auth.tokens import issue_token
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import (
    Constellation,
    ConstellationState,
    Job,
    JobState,
    Machine,
    MachineState,
    Role,
    Team,
    User,
    utcnow,
)

PASSWORD = "benchmark password"
PAGES = {
    "admin": ["/", "/jobs", "/audit"],
    "officer": ["/", "/teams", "/users"],
    "user": ["/"],
}
API = ["/api/v1/jobs", "/api/v1/teams", "/api/v1/users", "/api/v1/constellations"]


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def seed(env: dict[str, str]) -> dict[str, str]:
    """Fill a fresh database; return the admin's API token."""
    app = create_app(Config.from_env(env))
    migrate.upgrade(app)
    with app.app_context():
        password_hash = hash_password(PASSWORD)
        teams = [Team(name=f"Team {i:02d}") for i in range(30)]
        db.session.add_all(teams)
        db.session.flush()
        users = [
            User(
                email=f"user{i}@example.org",
                role=Role.USER,
                team_id=teams[i % 30].id,
                password_hash=password_hash,
            )
            for i in range(296)
        ]
        users += [
            User(email=f"officer{i}@example.org", role=Role.OFFICER, password_hash=password_hash)
            for i in range(3)
        ]
        admin = User(email="admin@example.org", role=Role.ADMIN, password_hash=password_hash)
        db.session.add_all([*users, admin])
        for team in teams:
            constellation = Constellation(
                name=f"vrc-{team.id}",
                kind="vrc",
                provider="local",
                team_id=team.id,
                state=ConstellationState.READY,
            )
            for n, role in enumerate(("router", "sim", "fc1", "fc2")):
                constellation.machines.append(
                    Machine(
                        name=role,
                        role=role,
                        state=MachineState.READY,
                        private_ip=f"10.{team.id}.0.{50 + n}",
                    )
                )
            db.session.add(constellation)
        now = utcnow()
        db.session.add_all(
            Job(
                id=str(uuid.uuid4()),
                kind="diagnostics",
                state=JobState.SUCCEEDED,
                team_id=teams[i % 30].id,
                progress=100,
                log="ok\n" * 20,
                created_at=now - timedelta(minutes=i),
            )
            for i in range(1000)
        )
        token = issue_token(admin, "bench").plaintext
        db.session.commit()  # services only flush: the seeding is the boundary here
        return {"Authorization": f"Bearer {token}"}


def log_in(base: str, email: str) -> requests.Session:
    session = requests.Session()
    page = session.get(f"{base}/login", timeout=30).text
    token = re.search(r'name="csrf_token" type="hidden" value="([^"]+)"', page)
    assert token
    response = session.post(
        f"{base}/login",
        timeout=30,
        data={"email": email, "password": PASSWORD, "csrf_token": token[1]},
    )
    assert response.url == f"{base}/", f"login as {email} failed"
    return session


def drive(base: str, headers: dict[str, str], clients: int, rounds: int) -> dict[str, list[float]]:
    """Run the clients; return the latencies (seconds) per request name."""
    timings: dict[str, list[float]] = {}
    lock = threading.Lock()
    errors: list[str] = []

    def client(number: int) -> None:
        kind = ("admin", "officer", "user")[number % 3]
        email = {
            "admin": "admin@example.org",
            "officer": f"officer{number % 3}@example.org",
            "user": f"user{number}@example.org",
        }[kind]
        session = log_in(base, email)
        api = requests.Session()
        api.headers.update(headers)
        for _ in range(rounds):
            for path in PAGES[kind]:
                requests_ = [(f"{kind} {path}", session, path)]
                if kind == "admin":
                    requests_ += [(f"api {p}", api, p) for p in API]
                for name, http, url in requests_:
                    start = time.perf_counter()
                    response = http.get(base + url, timeout=60)
                    elapsed = time.perf_counter() - start
                    with lock:
                        timings.setdefault(name, []).append(elapsed)
                        if response.status_code != 200:
                            errors.append(f"{name}: {response.status_code}")

    threads = [threading.Thread(target=client, args=(n,)) for n in range(clients)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    if errors:
        raise SystemExit(f"{len(errors)} failed requests, e.g. {errors[:3]}")
    return timings


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clients", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--database-url", help="default: SQLite in a temporary instance")
    args = parser.parse_args()
    instance = Path(tempfile.mkdtemp(prefix="cloudsim-bench-"))
    web = free_port()
    env = dict(
        os.environ,
        CLOUDSIM_INSTANCE_DIR=str(instance),
        CLOUDSIM_BIND=f"127.0.0.1:{web}",
        CLOUDSIM_REDIS_PORT=str(free_port()),
        CLOUDSIM_LOG_LEVEL="WARNING",
        CLOUDSIM_ADMIN_EMAIL="admin@example.org",
        CLOUDSIM_LOGIN_LIMIT="1000 per minute",
    )
    env.pop("CLOUDSIM_REDIS_URL", None)
    if args.database_url:
        env["CLOUDSIM_DATABASE_URL"] = args.database_url
    headers = seed(env)
    log = instance / "up.log"
    with log.open("wb") as out:
        stack = subprocess.Popen(
            [sys.executable, "-m", "cloudsim.cli", "up"],
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
            cwd=Path.cwd(),
        )
    try:
        deadline = time.monotonic() + 90
        while "CloudSim is running" not in log.read_text():
            if time.monotonic() > deadline or stack.poll() is not None:
                raise SystemExit(f"cloudsim up did not start:\n{log.read_text()}")
            time.sleep(0.2)
        base = f"http://127.0.0.1:{web}"
        started = time.perf_counter()
        timings = drive(base, headers, args.clients, args.rounds)
        wall = time.perf_counter() - started
    finally:
        stack.send_signal(signal.SIGINT)
        stack.wait(60)
    total = sum(len(v) for v in timings.values())
    print(
        f"web benchmark: {args.clients} clients, {total} requests in {wall:.1f} s "
        f"({total / wall:.0f} req/s), gunicorn {env.get('CLOUDSIM_WEB_WORKERS', '2')} workers, "
        f"{'PostgreSQL' if args.database_url else 'SQLite'}"
    )
    print("seeded: 30 teams, 120 machines, 300 users, 1,000 jobs")
    print(f"{'request':34} {'n':>5} {'p50 ms':>8} {'p95 ms':>8} {'p95/p50':>8}")
    for name, values in sorted(timings.items()):
        values.sort()
        p50 = statistics.median(values) * 1000
        p95 = values[int(0.95 * (len(values) - 1))] * 1000
        print(f"{name:34} {len(values):5d} {p50:8.1f} {p95:8.1f} {p95 / p50:8.2f}")


if __name__ == "__main__":
    main()
