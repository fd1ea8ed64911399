"""Benchmark team instances: change -> converged for 2 real instances, and the master's cost
per instance against lightweight stand-ins.

1. (root; skipped with --stand-ins-only) Two real team instances on local hosts, deployed by
   the master; a user created on the master: seconds until both instances have it (pushed by
   the sync jobs), and seconds of one reconcile (health + desired state) of both. Then the
   catch-up: one instance cut off (its pin broken), a user disabled on the master meanwhile;
   seconds from the instance answering again to the user disabled there, with the catch-up
   sent once a second as the beat does (against the convergence above, the reference).
2. The master's side of one poll (`check_instances`: desired state from the database, health
   and sync over pinned HTTPS, results written back) against 1, 10 and 30 stand-ins: loopback
   HTTPS servers in another process, each with its own certificate from the master's CA,
   answering the health check and the sync as an instance in sync does. Figures: wall time,
   the master's CPU time, per instance, and how they grow from 1 to 30 (the reference).

Usage: python -m bench.federation [--stand-ins-only]
"""

from __future__ import annotations

import json
import multiprocessing
import os
import shutil
import ssl
import sys
import tempfile
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from multiprocessing.connection import Connection
from pathlib import Path

from celery.contrib.testing.worker import start_worker
from flask import Flask
from sqlalchemy import select

from bench.provision import wait
from cloudsim.app import create_app
from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations.keys import deployment_ca
from cloudsim.models import (
    Constellation,
    ConstellationState,
    InstanceState,
    Role,
    Task,
    TeamInstance,
    User,
    utcnow,
)
from cloudsim.people.service import create_team, create_user, update_user
from cloudsim.providers.service import open_provider
from cloudsim.team_instances import service
from cloudsim.team_instances.client import Endpoint, call
from cloudsim.team_instances.poll import CATCH_UP_EVERY, catch_up, check_instances, endpoint_of
from provisioners.remote import pki
from tests.support.servers import RedisServer, bench_redis

STAND_INS = 30
USERS_PER_TEAM = 10
TASKS_PER_TEAM = 15


class _StandIn(BaseHTTPRequestHandler):
    """An instance in sync: healthy, and a sync changes nothing."""

    def _answer(self, body: dict[str, object]) -> None:
        data = json.dumps(body).encode()
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data)

    def do_GET(self) -> None:
        self._answer({"version": "stand-in", "database": True, "queue": True, "worker": True})

    def do_PUT(self) -> None:
        self.rfile.read(int(self.headers.get("Content-Length", "0")))
        self._answer({"changed": [], "reported": []})

    def log_message(self, *args: object) -> None:
        return None


def _serve_stand_ins(certs: list[tuple[str, str]], folder: str, reply: Connection) -> None:
    """Run one HTTPS server per certificate on loopback; send back their ports; serve forever."""
    ports = []
    for n, (cert, key) in enumerate(certs):
        (Path(folder) / f"{n}.crt").write_text(cert)
        (Path(folder) / f"{n}.key").write_text(key)
        context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
        context.load_cert_chain(Path(folder) / f"{n}.crt", Path(folder) / f"{n}.key")
        server = ThreadingHTTPServer(("127.0.0.1", 0), _StandIn)
        server.socket = context.wrap_socket(server.socket, server_side=True)
        threading.Thread(target=server.serve_forever, daemon=True).start()
        ports.append(server.server_address[1])
    reply.send(ports)
    threading.Event().wait()


def _config(folder: Path, redis: RedisServer, prefix: str, redis_db: int) -> Config:
    return Config.from_env(
        {
            "CLOUDSIM_INSTANCE_DIR": str(folder),
            # one Redis database each: the real part's worker must not get the stand-ins' jobs
            "CLOUDSIM_REDIS_URL": redis.url(redis_db),
            "CLOUDSIM_LOCAL_PREFIX": prefix,
            "CLOUDSIM_LOCAL_SUBNET_POOL": "10.219.0.0/16",
            "CLOUDSIM_LOCAL_PUBLIC_CIDR": "198.18.19.0/24",
            "CLOUDSIM_LOG_LEVEL": "WARNING",
            "CLOUDSIM_ARGON2_TIME_COST": "1",
            "CLOUDSIM_ARGON2_MEMORY_KIB": "1024",
        }
    )


def _seed_teams(count: int) -> list[int]:
    """Make teams with members and tasks; return the team ids."""
    now = utcnow()
    ids = []
    for t in range(count):
        team = create_team(SYSTEM, f"Team {t}")
        for u in range(USERS_PER_TEAM):
            create_user(SYSTEM, email=f"u{u}@team{t}.example.org", team_id=team.id, name=f"U {u}")
        for k in range(TASKS_PER_TEAM):
            db.session.add(
                Task(
                    team_id=team.id,
                    name=f"Task {k}",
                    world="vrc_task_2",
                    run_config=1,
                    window_start=now,
                    window_stop=now.replace(year=now.year + 1),
                    uplink_bits=1_000_000,
                    downlink_bits=8_000_000,
                )
            )
        ids.append(team.id)
    for o in range(3):
        create_user(SYSTEM, email=f"officer{o}@example.org", role=Role.OFFICER)
    db.session.commit()
    return ids


def stand_ins(folder: Path, redis: RedisServer) -> list[tuple[int, float, float, float]]:
    """Return (instances, wall s, master CPU s, desired-state bytes per instance) per size."""
    app = create_app(_config(folder / "stand-ins", redis, "csbfs", 1))
    with app.app_context():
        db.create_all()
        teams = _seed_teams(STAND_INS)
        ca = deployment_ca()
        issued = [pki.issue_tls_server(ca, f"stand-in-{n}", ["127.0.0.1"]) for n in teams]
        ours, theirs = multiprocessing.Pipe()
        server = multiprocessing.get_context("spawn").Process(
            target=_serve_stand_ins,
            args=([(c.cert_pem, c.key_pem) for c in issued], str(folder), theirs),
            daemon=True,
        )
        server.start()
        ports = ours.recv()
        endpoints: dict[int, Endpoint] = {}
        for n, team_id in enumerate(teams):
            constellation = Constellation(
                name=f"si-{n}", kind="cloudsim", provider="local", state=ConstellationState.READY
            )
            instance = TeamInstance(
                name=f"si-{n}",
                team_id=team_id,
                constellation=constellation,
                state=InstanceState.READY,
                cert_fingerprint=pki.certificate_fingerprint(issued[n].cert_pem),
            )
            db.session.add(instance)
            db.session.flush()
            endpoints[instance.id] = Endpoint(
                "127.0.0.1",
                ports[n],
                ca.cert_pem,
                instance.cert_fingerprint or "",
                "cst_stand-in",
            )
        db.session.commit()
        ids = sorted(endpoints)
        config = app.config["CLOUDSIM"]

        def connect(instance: TeamInstance, _: Config) -> Endpoint:
            return endpoints[instance.id]

        from cloudsim.team_instances.sync import desired_state

        size = len(json.dumps(desired_state(db.session.get(TeamInstance, ids[0]))))  # type: ignore[arg-type]
        results = []
        check_instances(config, ids[:1], connect)  # warm up (imports, first TLS context)
        db.session.commit()
        for count in (1, 10, STAND_INS):
            wall, cpu = [], []
            for _ in range(3):
                db.session.expire_all()
                started, cpu_started = time.perf_counter(), time.process_time()
                checked = check_instances(config, ids[:count], connect)
                db.session.commit()
                wall.append(time.perf_counter() - started)
                cpu.append(time.process_time() - cpu_started)
                assert all(i.state == InstanceState.READY and i.sync_error is None for i in checked)
            results.append((count, min(wall), min(cpu), float(size)))
        server.kill()
        server.join()
    return results


def _has_user(app: Flask, instance_id: int, email: str) -> bool:
    with app.app_context():
        instance = db.session.get(TeamInstance, instance_id)
        assert instance is not None
        endpoint = endpoint_of(instance, app.config["CLOUDSIM"])
        return email in {u["email"] for u in call(endpoint, "GET", "/users?page_size=500")}


def _active(app: Flask, instance_id: int, email: str) -> bool:
    with app.app_context():
        instance = db.session.get(TeamInstance, instance_id)
        assert instance is not None
        endpoint = endpoint_of(instance, app.config["CLOUDSIM"])
        users = call(endpoint, "GET", "/users?page_size=500")
        return bool(next(u for u in users if u["email"] == email)["active"])


def _catch_up_seconds(app: Flask, instance_id: int, email: str) -> float:
    """Cut the instance off (pin broken), disable a user on the master, let the instance
    answer again; return the seconds until the user is disabled there (beat ticks each 1 s)."""
    config = app.config["CLOUDSIM"]
    instance = db.session.get(TeamInstance, instance_id)
    assert instance is not None
    pinned, instance.cert_fingerprint = instance.cert_fingerprint, "00" * 32
    db.session.commit()
    user = db.session.scalar(select(User).where(User.email == email))
    assert user is not None
    update_user(SYSTEM, user.id, active=False)
    db.session.commit()  # its sync job fails: the instance cannot be reached
    while True:
        db.session.expire_all()
        if db.session.get(TeamInstance, instance_id).sync_error:  # type: ignore[union-attr]
            break
        time.sleep(0.1)
    instance = db.session.get(TeamInstance, instance_id)
    assert instance is not None
    instance.cert_fingerprint = pinned
    db.session.commit()
    started, last_tick = time.perf_counter(), 0.0
    while _active(app, instance_id, email):
        if time.perf_counter() - last_tick >= CATCH_UP_EVERY.total_seconds():
            last_tick = time.perf_counter()
            db.session.expire_all()
            catch_up(config)
            db.session.commit()
        time.sleep(0.05)
    return time.perf_counter() - started


def real_instances(folder: Path, redis: RedisServer) -> tuple[float, float, float, float]:
    """Return (deploy s, change -> both converged s, one reconcile of both s, catch-up s)."""
    app = create_app(_config(folder / "real", redis, "csbfr", 0))
    try:
        with app.app_context():
            db.create_all()
            teams = _seed_teams(2)
            with start_worker(
                app.extensions["celery"],
                pool="threads",
                concurrency=3,
                perform_ping_check=False,
                loglevel="WARNING",
                shutdown_timeout=60,
            ):
                started = time.perf_counter()
                deployed = [
                    service.deploy(SYSTEM, name=f"bf-{n}", provider="local", team_id=t)[0]
                    for n, t in enumerate(teams)
                ]
                db.session.commit()
                wait([job.id for _, job in deployed])
                ids = [instance.id for instance, _ in deployed]
                deadline = time.monotonic() + 180
                while not all(
                    i.state == InstanceState.READY
                    for i in check_instances(app.config["CLOUDSIM"], ids)
                ):
                    db.session.commit()
                    if time.monotonic() > deadline:
                        raise SystemExit("the instances never became ready")
                    time.sleep(1)
                db.session.commit()
                deploy = time.perf_counter() - started
                started = time.perf_counter()
                emails = []
                for team_id in teams:
                    email = f"new{team_id}@example.org"
                    create_user(SYSTEM, email=email, team_id=team_id)
                    emails.append(email)
                db.session.commit()  # starts one sync job per instance
                while not all(_has_user(app, i, e) for i, e in zip(ids, emails, strict=True)):
                    time.sleep(0.1)
                converged = time.perf_counter() - started
                started = time.perf_counter()
                check_instances(app.config["CLOUDSIM"], ids)
                db.session.commit()
                reconcile = time.perf_counter() - started
                caught_up = _catch_up_seconds(app, ids[0], emails[0])
    finally:
        with app.app_context():
            open_provider("local", app.config["CLOUDSIM"]).driver.ex_sweep()  # type: ignore[attr-defined]
    return deploy, converged, reconcile, caught_up


def main() -> None:
    only_stand_ins = "--stand-ins-only" in sys.argv
    if not only_stand_ins and os.geteuid() != 0:
        raise SystemExit("bench/federation.py needs root (or --stand-ins-only)")
    folder = Path(tempfile.mkdtemp(prefix="cloudsim-bench-federation-"))
    redis = bench_redis(folder)
    try:
        sizes = stand_ins(folder, redis)
        real = None if only_stand_ins else real_instances(folder, redis)
    finally:
        redis.stop()
        shutil.rmtree(folder, ignore_errors=True)
    print("team instances benchmark")
    if real is not None:
        deploy, converged, reconcile, caught_up = real
        print(f"  2 real instances (local hosts) deployed and ready   {deploy:7.1f} s")
        print(f"  a user made on the master -> on both instances      {converged:7.2f} s")
        print(f"  one reconcile of both (health + desired state)      {reconcile:7.2f} s")
        print(
            f"  catch-up: instance answers again -> a user disabled "
            f"meanwhile is disabled there {caught_up:5.2f} s "
            f"(ratio to a change reaching a reachable instance: {caught_up / converged:4.2f}; "
            f"promised: within 2 s)"
        )
    print(
        f"  master's side of one poll against stand-ins ({USERS_PER_TEAM} users, "
        f"{TASKS_PER_TEAM} tasks per team; {sizes[0][3] / 1024:.1f} KiB of desired state each)"
    )
    one_cpu = sizes[0][2]
    for count, wall, cpu, _ in sizes:
        print(
            f"    {count:3d} instances: wall {wall:6.3f} s, master CPU {cpu:6.3f} s "
            f"= {1000 * cpu / count:5.1f} ms per instance "
            f"(ratio to 1 instance: {cpu / count / one_cpu:4.2f})"
        )
    total = sizes[-1]
    print(
        f"  growth: {total[0]} instances cost {total[2] / one_cpu:.1f} x one instance's CPU "
        f"(linear would be {total[0]}); wall {total[1] / sizes[0][1]:.1f} x "
        f"(calls run 8 at a time)"
    )


if __name__ == "__main__":
    main()
