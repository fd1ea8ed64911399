"""Benchmark the web app at season scale: p50/p95 and queries of every page and API list.

Seeds a season (30 teams, 120 machines, 300 users, 1,000 jobs, 450 finished runs with score
events and stored score and bandwidth logs) into a fresh instance, starts the production stack
with `cloudsim up` (gunicorn, private Redis) on free loopback ports, counts each page's SQL
statements in-process, and drives every GET page and API list an admin, an officer and a team
user may open with concurrent clients, against the anonymous login page as the reference.
Usage: python -m bench.web [--db sqlite|postgresql|both] [--clients 20] [--rounds 8]
"""

from __future__ import annotations

import argparse
import os
import random
import re
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import requests
from flask import Flask
from flask.testing import FlaskClient
from sqlalchemy import event, func, select

from cloudsim import migrate
from cloudsim.app import create_app
from cloudsim.auth.passwords import hash_password
from cloudsim.auth.tokens import issue_token
from cloudsim.competition.artifacts import LogStore
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import Job, Machine, Role, Run, ScoreEvent, Team, User
from tests.support.season import add_credentials, add_season, new_teams, team_urls
from tests.support.servers import PostgresServer
from tests.web.test_authorization_matrix import MATRIX, PERSONAS

PASSWORD = "benchmark password"
# What bench/season.py's clients load: the dashboards and the main API lists.
PAGES = {
    "admin": ["/", "/jobs", "/audit"],
    "officer": ["/", "/teams", "/users"],
    "user": ["/"],
}
API = ["/api/v1/jobs", "/api/v1/teams", "/api/v1/users", "/api/v1/constellations"]
REFERENCE = "/login"  # anonymous, no query: what the stack costs around any page
KINDS = ("admin", "officer", "user")
MATRIX_PERSONA = {"admin": "admin", "officer": "officer", "user": "user_a"}


@dataclass(frozen=True)
class Visitor:
    """Who a client logs in as, and the requests (name, path) it makes each round."""

    email: str
    requests: list[tuple[str, str]]
    headers: dict[str, str] = field(default_factory=dict)  # its API token


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def seed(env: dict[str, str], runs: int = 15) -> dict[str, str]:
    """Fill a fresh database with a season (`runs` finished runs per team); return the
    admin's API headers."""
    app = create_app(Config.from_env(env))
    migrate.upgrade(app)
    with app.app_context():
        password_hash = hash_password(PASSWORD)
        teams = new_teams(30)
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
        for user in users:
            add_credentials(user, 1)
        store = LogStore(app.config["CLOUDSIM"])
        # a 30-minute run's bandwidth log: what the run page charts
        add_season(
            store, teams, password_hash, users=0, runs=runs, jobs=34, events=8, log_seconds=1800
        )
        token = issue_token(admin, "bench").plaintext
        db.session.commit()  # services only flush: the seeding is the boundary here
        return {"Authorization": f"Bearer {token}"}


def seeded(app: Flask) -> str:
    """Say what the database holds."""
    with app.app_context():
        count = {
            m.__name__: db.session.scalar(select(func.count()).select_from(m))
            for m in (Team, User, Machine, Job, Run, ScoreEvent)
        }
    return (
        f"{count['Team']} teams, {count['Machine']} machines, {count['User']} users, "
        f"{count['Job']:,} jobs, {count['Run']} finished runs, {count['ScoreEvent']:,} score events"
    )


def season_visitors(app: Flask) -> dict[str, Visitor]:
    """Return per kind the visitor opening every GET page and API list it may (team 1's rows)."""
    with app.app_context():
        team = db.session.scalar(select(Team).order_by(Team.id).limit(1))
        assert team is not None
        gets = {endpoint for endpoint, method in MATRIX if method == "GET"}
        urls = team_urls(app, team.id, gets)
        member = db.session.scalar(
            select(User).where(User.team_id == team.id).order_by(User.id).limit(1)
        )
        assert member is not None
        emails = {
            "admin": "admin@example.org",
            "officer": "officer0@example.org",
            "user": member.email,
        }
        visitors = {}
        for kind, email in emails.items():
            user = db.session.scalar(select(User).where(User.email == email))
            assert user is not None
            column = PERSONAS.index(MATRIX_PERSONA[kind])
            visitors[kind] = Visitor(
                email,
                [
                    (f"{kind} {e}", u)
                    for e, u in sorted(urls.items())
                    if MATRIX[(e, "GET")][column] == 200
                ],
                {"Authorization": f"Bearer {issue_token(user, 'bench').plaintext}"},
            )
        db.session.commit()
        return visitors


def default_visitor(number: int, headers: dict[str, str]) -> Visitor:
    """Return the n-th client's visitor of the dashboards benchmark (admins add the API lists)."""
    kind = KINDS[number % 3]
    email = {
        "admin": "admin@example.org",
        "officer": f"officer{number % 3}@example.org",
        "user": f"user{number}@example.org",
    }[kind]
    paths = [(f"{kind} {p}", p) for p in PAGES[kind]]
    if kind == "admin":
        paths += [(f"api {p}", p) for p in API] * len(PAGES[kind])
    return Visitor(email, paths, headers if kind == "admin" else {})


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


def drive(
    base: str,
    headers: dict[str, str],
    clients: int,
    rounds: int,
    visitor: Callable[[int], Visitor] | None = None,
) -> dict[str, list[float]]:
    """Run the clients; return the latencies (seconds) per request name.

    Client n is `visitor(n)` (default: the dashboards and, for admins, the API lists).
    """
    pick = visitor or (lambda number: default_visitor(number, headers))
    timings: dict[str, list[float]] = {}
    lock = threading.Lock()
    errors: list[str] = []
    resent: list[str] = []

    def client(number: int) -> None:
        me = pick(number)
        session = log_in(base, me.email)
        api = requests.Session()
        api.headers.update(me.headers)
        anonymous = requests.Session()
        # Clients in lockstep would all wait behind the same heavy request: each its own order.
        order = random.Random(number)
        for _ in range(rounds):
            batch = [*me.requests, (f"reference GET {REFERENCE} (anonymous)", REFERENCE)]
            order.shuffle(batch)
            for name, url in batch:
                http = api if url.startswith("/api/") else session
                http = anonymous if url == REFERENCE else http
                start = time.perf_counter()
                try:
                    response = http.get(base + url, timeout=60)
                except requests.ConnectionError:
                    # The server closed this kept-alive connection as the request left (its
                    # keep-alive timeout): a browser sends the GET again, and so do we, timed.
                    resent.append(name)
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
    if resent:
        print(f"{len(resent)} request(s) sent again on a new connection, e.g. {resent[:3]}")
    return timings


def visits(
    app: Flask, visitors: Iterable[Visitor]
) -> Iterator[tuple[str, str, FlaskClient, dict[str, str]]]:
    """Yield each visitor's requests (and the reference) as (name, url, logged-in test client,
    API headers), for measuring in-process."""
    for me in visitors:
        client = app.test_client()
        page = client.get("/login").get_data(as_text=True)
        token = re.search(r'name="csrf_token" type="hidden" value="([^"]+)"', page)
        assert token
        form = {"email": me.email, "password": PASSWORD, "csrf_token": token[1]}
        assert client.post("/login", data=form).status_code == 302
        for name, url in [*me.requests, (f"reference GET {REFERENCE} (anonymous)", REFERENCE)]:
            http = app.test_client() if url == REFERENCE else client
            yield name, url, http, me.headers if url.startswith("/api/") else {}


def count_queries(app: Flask, visitors: dict[str, Visitor]) -> dict[str, int]:
    """Return the SQL statements each request makes, counted in-process."""
    counts: dict[str, int] = {}
    statements: list[str] = []
    with app.app_context():
        engine = db.engine
    # Requests outside any app context of ours: each gets its own, as under gunicorn.
    listen = lambda *args: statements.append(args[2])  # noqa: E731
    event.listen(engine, "before_cursor_execute", listen)
    try:
        for name, url, http, headers in visits(app, visitors.values()):
            statements.clear()
            http.get(url, headers=headers).get_data()  # a streamed answer queries as read
            counts[name] = len(statements)
    finally:
        event.remove(engine, "before_cursor_execute", listen)
    return counts


@contextmanager
def stack(env: dict[str, str], instance: Path) -> Iterator[str]:
    """Run `cloudsim up` with env; yield its base URL; stop it with Ctrl-C."""
    log = instance / "up.log"
    with log.open("wb") as out:
        process = subprocess.Popen(
            [sys.executable, "-m", "cloudsim.cli", "up"],
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
            cwd=Path.cwd(),
        )
    try:
        deadline = time.monotonic() + 90
        while "CloudSim is running" not in log.read_text():
            if time.monotonic() > deadline or process.poll() is not None:
                raise SystemExit(f"cloudsim up did not start:\n{log.read_text()}")
            time.sleep(0.2)
        yield f"http://127.0.0.1:{env['CLOUDSIM_BIND'].rsplit(':', 1)[1]}"
    finally:
        process.send_signal(signal.SIGINT)
        process.wait(60)


def bench_env(instance: Path, database_url: str | None) -> dict[str, str]:
    env = dict(
        os.environ,
        CLOUDSIM_INSTANCE_DIR=str(instance),
        CLOUDSIM_BIND=f"127.0.0.1:{free_port()}",
        CLOUDSIM_REDIS_PORT=str(free_port()),
        CLOUDSIM_LOG_LEVEL="WARNING",
        CLOUDSIM_ADMIN_EMAIL="admin@example.org",
        CLOUDSIM_LOGIN_LIMIT="1000 per minute",
    )
    env.pop("CLOUDSIM_REDIS_URL", None)
    if database_url:
        env["CLOUDSIM_DATABASE_URL"] = database_url
    return env


def measure(label: str, database_url: str | None, clients: int, rounds: int) -> None:
    """Seed a season on one database, load it, print the table."""
    instance = Path(tempfile.mkdtemp(prefix="cloudsim-bench-"))
    try:
        env = bench_env(instance, database_url)
        started = time.perf_counter()
        seed(env)
        seeding = time.perf_counter() - started
        app = create_app(Config.from_env(env))
        visitors = season_visitors(app)
        kinds = [visitors[KINDS[n % 3]] for n in range(clients)]
        with stack(env, instance) as base:
            queries = count_queries(app, visitors)
            stack_floor(base, [kinds[n].email for n in range(clients)])
            started, machine, own = time.perf_counter(), busy_cpu_seconds(), time.process_time()
            timings = drive(base, {}, clients, rounds, lambda number: kinds[number])
            wall = time.perf_counter() - started
            machine, own = busy_cpu_seconds() - machine, time.process_time() - own
        config = app.config["CLOUDSIM"]
        server = f"gunicorn {config.web_workers} workers x {config.web_threads} threads"
        report(label, seeded(app), seeding, timings, queries, wall, clients, server)
        print(
            f"CPU while driving: the machine's {os.cpu_count()} cores {machine / wall:.2f} cores "
            "busy (everything, other users included), the clients' own process "
            f"{own / wall:.2f} cores"
        )
    finally:
        shutil.rmtree(instance, ignore_errors=True)


def stack_floor(base: str, emails: list[str], rounds: int = 100) -> None:
    """Print what the same clients get asking only the login page: the stack's own limit."""
    started = time.perf_counter()
    timings = drive(base, {}, len(emails), rounds, lambda number: Visitor(emails[number], []))
    wall = time.perf_counter() - started
    values = sorted(v for vs in timings.values() for v in vs)
    print(
        f"the stack alone ({len(emails)} clients asking only {REFERENCE}, {len(values)} requests): "
        f"{len(values) / wall:.0f} req/s, p50 {1000 * values[len(values) // 2]:.1f} ms, "
        f"p95 {1000 * values[int(0.95 * (len(values) - 1))]:.1f} ms (each client's login included)"
    )


def busy_cpu_seconds() -> float:
    """Return the CPU seconds all cores have been busy since boot (/proc/stat)."""
    fields = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:9]]
    idle = fields[3] + fields[4]  # idle and iowait
    return (sum(fields) - idle) / os.sysconf("SC_CLK_TCK")


def report(
    label: str,
    what: str,
    seeding: float,
    timings: dict[str, list[float]],
    queries: dict[str, int],
    wall: float,
    clients: int,
    server: str,
) -> None:
    total = sum(len(v) for v in timings.values())
    load = os.getloadavg()
    print(
        f"\nweb benchmark on {label}: {clients} clients, {total} requests in {wall:.1f} s "
        f"({total / wall:.0f} req/s), {server}; "
        f"load average {load[0]:.1f} {load[1]:.1f} {load[2]:.1f}"
    )
    print(f"seeded in {seeding:.0f} s: {what}")
    print(
        f"{clients} clients that never pause: mean latency = clients / rate = "
        f"{1000 * clients / (total / wall):.0f} ms (Little's law), whatever a page costs"
    )

    def p95(values: list[float]) -> float:
        return sorted(values)[int(0.95 * (len(values) - 1))] * 1000

    reference = next(v for k, v in timings.items() if k.startswith("reference"))
    ref95 = p95(reference)
    print(f"{'request':44} {'n':>4} {'queries':>7} {'p50 ms':>7} {'p95 ms':>7} {'p95/ref':>7}")
    slow = []
    for name, values in sorted(timings.items()):
        p50 = statistics.median(values) * 1000
        worst = p95(values)
        mark = " *" if worst >= 100 else ""
        if mark:
            slow.append(name)
        print(
            f"{name:44} {len(values):4d} {queries.get(name, 0):7d} {p50:7.1f} {worst:7.1f} "
            f"{worst / ref95:7.2f}{mark}"
        )
    print(f"p95 >= 100 ms (*): {', '.join(slow) if slow else 'none'}")


def main() -> None:
    on_each_database(arguments(__doc__ or "", "both", 8).parse_args(), measure)


def arguments(doc: str, db: str, rounds: int) -> argparse.ArgumentParser:
    """Return the command line of a bench that loads pages on one database or both."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--db", choices=("sqlite", "postgresql", "both"), default=db)
    parser.add_argument("--clients", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=rounds)
    parser.add_argument("--database-url", help="a PostgreSQL to use instead of a private one")
    return parser


def on_each_database(
    args: argparse.Namespace, measure: Callable[[str, str | None, int, int], None]
) -> None:
    """Call measure(label, database URL, clients, rounds) on the databases args name."""
    if args.db in ("sqlite", "both"):
        measure("SQLite", None, args.clients, args.rounds)
    if args.db in ("postgresql", "both"):
        if args.database_url:
            measure("PostgreSQL", args.database_url, args.clients, args.rounds)
            return
        server = PostgresServer()  # the test harness's private cluster, stopped by its PID
        try:
            url = server.create_database("cloudsim_bench")
            measure("PostgreSQL (private, fsync off)", url, args.clients, args.rounds)
        finally:
            server.stop()


if __name__ == "__main__":
    main()
