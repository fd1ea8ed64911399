"""A master serving its portal over HTTPS (gunicorn, its own process) and a team instance
that got its portal settings through the documented desired state."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import timedelta
from pathlib import Path
from typing import Any

from flask import Flask
from sqlalchemy import select

from cloudsim.app import create_app
from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import (
    Constellation,
    ConstellationState,
    Role,
    Run,
    RunState,
    ScoreEvent,
    Task,
    TeamInstance,
    utcnow,
)
from cloudsim.people.service import create_team
from cloudsim.portal.credentials import upload_token, write_certificate
from cloudsim.portal.plausibility import PROOF_LOGS
from cloudsim.team_instances.sync import desired_state
from tests.competition.support import open_task, store_log
from tests.conftest import IsolatedClient, make_user, token_for
from tests.support.servers import port_accepts, wait_for


class MasterServer:
    """The master's web server (gunicorn with the portal's certificate) on 127.0.0.1."""

    def __init__(self, config: Config, port: int, root: Path) -> None:
        self.config, self.port, self.root = config, port, root
        self.process: subprocess.Popen[bytes] | None = None

    def start(self) -> None:
        cert, key = (
            self.config.instance_dir / "tls" / "portal.crt",
            self.config.instance_dir / "tls" / "portal.key",
        )
        env = dict(
            os.environ,
            CLOUDSIM_INSTANCE_DIR=str(self.config.instance_dir),
            CLOUDSIM_DATABASE_URL=self.config.database_url,
            CLOUDSIM_REDIS_URL=self.config.effective_redis_url,
            CLOUDSIM_ENCRYPTION_KEYS=",".join(self.config.encryption_keys),
            CLOUDSIM_SECRET_KEY=self.config.secret_key,
            CLOUDSIM_PORTAL_URL=self.config.portal_url,
            CLOUDSIM_LOG_LEVEL="WARNING",
            PYTHONPATH=str(self.root),
        )
        argv = [
            sys.executable,
            "-m",
            "gunicorn",
            "--bind",
            f"127.0.0.1:{self.port}",
            "--workers",
            "1",
            "--certfile",
            str(cert),
            "--keyfile",
            str(key),
            "--log-level",
            "warning",
            "cloudsim.wsgi:app",
        ]
        self.process = subprocess.Popen(
            argv, env=env, cwd=self.root, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        wait_for(lambda: port_accepts(self.port), 30, "the master's web server")

    def kill(self) -> None:
        """Stop it the hard way (as a crash or a pulled cable would), its worker included."""
        if self.process is None:
            return
        children = Path(f"/proc/{self.process.pid}/task/{self.process.pid}/children")
        pids = [int(p) for p in children.read_text().split()] if children.exists() else []
        for pid in [self.process.pid, *pids]:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        self.process.wait()
        self.process = None
        # its worker may hold the listening socket a moment longer: a restart must not
        # mistake the dying one for the new one
        wait_for(lambda: not port_accepts(self.port), 10, "the old server gone")


@dataclass
class Portal:
    """A master (its app, its server) with a team instance for Team A (the test's app) and
    one for Team B."""

    master: Flask
    server: MasterServer
    instance_id: int  # Team A's TeamInstance on the master
    other_instance_id: int  # Team B's
    task_ids: dict[str, int]  # the master's tasks by name
    officer_token: dict[str, str]
    user_token: dict[str, str]

    @contextmanager
    def on_master(self) -> Iterator[None]:
        with self.master.app_context():
            yield
            db.session.commit()

    def master_client(self) -> IsolatedClient:
        return self.master.test_client()  # type: ignore[return-value]

    def upload_token(self) -> str:
        with self.on_master():
            return upload_token(db.session.get(TeamInstance, self.instance_id))  # type: ignore[arg-type]


def start_master(config: Config, root: Path) -> Portal:
    """Make a master (teams A and B, their tasks, an officer, an instance each) and serve it."""
    master = create_app(config)
    master.test_client_class = IsolatedClient
    with master.app_context():
        db.create_all()
        team_a, team_b = create_team(SYSTEM, "Team A"), create_team(SYSTEM, "Team B")
        opened = utcnow() - timedelta(hours=2)
        tasks = {
            "Driving 1": open_task(team_a.id, name="Driving 1", window_start=opened).id,
            "Driving 2": open_task(team_a.id, name="Driving 2", window_start=opened).id,
            "Theirs": open_task(team_b.id, name="Theirs", window_start=opened).id,
        }
        officer, user = make_user(Role.OFFICER), make_user(Role.USER, team_a)
        instance, other = (
            TeamInstance(
                name=name,
                team=team,
                constellation=Constellation(
                    name=name, kind="cloudsim", provider="local", state=ConstellationState.READY
                ),
            )
            for name, team in (("ti-a", team_a), ("ti-b", team_b))
        )
        db.session.add_all([instance, other])
        db.session.flush()
        write_certificate(config, config.instance_dir / "tls")
        portal = Portal(
            master,
            MasterServer(config, int(config.portal_url.rsplit(":", 1)[1].strip("/")), root),
            instance.id,
            other.id,
            tasks,
            token_for(officer),
            token_for(user),
        )
        db.session.commit()
    portal.server.start()
    return portal


def sync_instance(portal: Portal, client: Any, instance_id: int | None = None) -> dict[str, Any]:
    """Send an instance (Team A's unless told) its desired state from the master, through the
    documented API."""
    with portal.on_master():
        instance = db.session.get(TeamInstance, instance_id or portal.instance_id)
        assert instance is not None
        state = json.loads(json.dumps(desired_state(instance)))
    admin = token_for(make_user(Role.ADMIN))
    answer = client.put("/api/v1/instance/desired-state", json=state, headers=admin)
    assert answer.status_code == 200, answer.json
    return state


def finished_run(
    task_name: str,
    logs: dict[str, bytes],
    tmp: Path,
    *,
    score: int = 2,
    uplink_bits_used: int = 50_000,
    started_ago: timedelta = timedelta(minutes=20),
) -> Run:
    """On the instance: a finished run of the master's task with its logs stored (committed)."""
    task = db.session.scalar(select(Task).where(Task.name == task_name))
    assert task is not None and task.master_key, "the instance has the master's task"
    started = utcnow() - started_ago
    run = Run(
        task_id=task.id,
        team_id=task.team_id,
        state=RunState.FINISHED,
        score=score,
        falls=1,
        sim_seconds=600.0,
        uplink_bits_used=uplink_bits_used,
        downlink_bits_used=9_000_000,
        end_reason="time_limit",
        started_at=started,
        running_at=started,
        finished_at=started + timedelta(minutes=10),
    )
    run.score_events = [
        ScoreEvent(
            kind="checkpoint",
            checkpoint=n,
            points=1,
            sim_time=100.0 * n,
            wall_time=started + timedelta(seconds=100 * n),
        )
        for n in range(1, score + 1)
    ]
    db.session.add(run)
    db.session.flush()
    folder = tmp / f"logs-{run.id}"
    folder.mkdir(parents=True)
    # a finished run declares what it is re-simulated from: empty unless the test gives them
    proof = {name: b"" for name in PROOF_LOGS if name not in logs}
    for name, content in {**logs, **proof}.items():
        (folder / name).write_bytes(content)
        store_log(run, folder / name, name)
    db.session.commit()
    return run
