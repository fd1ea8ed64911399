"""`cloudsim worker` and `cloudsim beat` run only a worker or only the beat against the
database and Redis the settings name (PostgreSQL here), as a second machine would."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from click.testing import CliRunner
from flask import Flask

from cloudsim.auth.policy import SYSTEM
from cloudsim.cli import main
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.jobs.service import enqueue
from cloudsim.models import Job, JobState
from cloudsim.monitoring import heartbeats
from cloudsim.monitoring.health import redis_client
from tests.conftest import running_app
from tests.support.servers import PostgresServer, wait_for


def _env(config: Config, instance: Path) -> dict[str, str]:
    """The settings a worker machine gets: the master's database, Redis and keys; its own
    instance folder."""
    return dict(
        os.environ,
        CLOUDSIM_INSTANCE_DIR=str(instance),
        CLOUDSIM_DATABASE_URL=config.database_url,
        CLOUDSIM_REDIS_URL=config.effective_redis_url,
        CLOUDSIM_ENCRYPTION_KEYS=",".join(config.encryption_keys),
        CLOUDSIM_SECRET_KEY=config.secret_key,
        CLOUDSIM_WORKER_CONCURRENCY="1",
        CLOUDSIM_LOG_LEVEL="WARNING",
    )


@contextmanager
def _running(command: str, env: dict[str, str], log: Path) -> Iterator[subprocess.Popen[bytes]]:
    with log.open("wb") as out:
        process = subprocess.Popen(
            [sys.executable, "-m", "cloudsim.cli", command], env=env, stdout=out, stderr=out
        )
    try:
        yield process
    finally:
        process.send_signal(signal.SIGTERM)  # Celery's warm shutdown
        assert process.wait(60) is not None


@pytest.fixture
def master(make_config: Callable[..., Config], postgres_server: PostgresServer) -> Iterator[Flask]:
    url = postgres_server.create_database(f"cloudsim_workers_{uuid.uuid4().hex[:8]}")
    with running_app(make_config(url)) as app:
        yield app


def test_a_worker_alone_runs_jobs_and_is_heard_from(master: Flask, tmp_path: Path) -> None:
    config = master.config["CLOUDSIM"]
    env = _env(config, tmp_path / "worker-machine")
    with _running("worker", env, tmp_path / "worker.log"):
        job = enqueue("diagnostics", SYSTEM)
        db.session.commit()

        def finished() -> bool:
            db.session.rollback()  # see the worker's commits
            state = db.session.get(Job, job.id).state  # type: ignore[union-attr]
            assert state != JobState.FAILED, db.session.get(Job, job.id).error  # type: ignore[union-attr]
            return state == JobState.SUCCEEDED

        wait_for(finished, 180, "the diagnostics job on the lone worker")

        def heard_from() -> dict[str, float]:  # recorded just after the task's commit
            seen = heartbeats.heard(redis_client(config))
            return seen if any(who.startswith(heartbeats.WORKER) for who in seen) else {}

        seen = wait_for(heard_from, 30, "the worker's heartbeat")
        assert isinstance(seen, dict) and heartbeats.BEAT not in seen  # no beat runs here


def test_the_beat_alone_is_heard_from(master: Flask, tmp_path: Path) -> None:
    config = master.config["CLOUDSIM"]
    env = _env(config, tmp_path / "beat-machine")
    with _running("beat", env, tmp_path / "beat.log"):
        wait_for(
            lambda: heartbeats.BEAT in heartbeats.heard(redis_client(config)),
            120,
            "the beat's heartbeat",
        )
    assert not any(
        who.startswith(heartbeats.WORKER) for who in heartbeats.heard(redis_client(config))
    )


def test_a_worker_without_the_masters_redis_is_refused(tmp_path: Path) -> None:
    env = {"CLOUDSIM_INSTANCE_DIR": str(tmp_path / "instance")}
    result = CliRunner().invoke(main, ["worker"], env=env)
    assert result.exit_code == 1
    assert "set CLOUDSIM_REDIS_URL" in result.output
