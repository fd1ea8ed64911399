"""GET /healthz and /readyz, and `cloudsim status`: each part named, no secret, 503 when down."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from datetime import timedelta
from pathlib import Path

import pytest
from click.testing import CliRunner
from flask import Flask

from cloudsim.cli import main
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import PortalUpload, Team, utcnow
from cloudsim.monitoring import heartbeats
from tests.competition.support import finished_run, open_task
from tests.conftest import running_app
from tests.support.servers import RedisServer

PARTS = {"database", "redis", "workers", "beat", "disk", "outbox"}


def _hear_everyone(app: Flask) -> None:
    url = app.config["CLOUDSIM"].effective_redis_url
    heartbeats.note(url, heartbeats.WORKER + "cloudsim@test")
    heartbeats.note(url, heartbeats.BEAT)


def test_healthz_answers_with_nothing_else_up(app: Flask) -> None:
    response = app.test_client().get("/healthz")
    assert response.status_code == 200
    assert response.json == {"status": "alive"}


def test_readyz_names_the_silent_worker_and_beat_and_tells_no_secret(app: Flask) -> None:
    config = app.config["CLOUDSIM"]
    response = app.test_client().get("/readyz")
    assert response.status_code == 503
    body = response.json
    assert set(body["checks"]) == PARTS
    assert body["failing"] == ["workers", "beat"]
    assert body["checks"]["workers"]["detail"] == "never heard from"
    text = response.get_data(as_text=True)
    for secret in (config.secret_key, *config.encryption_keys, config.effective_redis_url):
        assert secret not in text

    _hear_everyone(app)
    response = app.test_client().get("/readyz")
    assert response.status_code == 200, response.json
    assert response.json["status"] == "ready" and response.json["failing"] == []


def test_readyz_fails_on_a_worker_heard_from_too_long_ago(app: Flask) -> None:
    _hear_everyone(app)
    url = app.config["CLOUDSIM"].effective_redis_url
    heartbeats.note(url, heartbeats.WORKER + "cloudsim@test", at=time.time() - 300)
    body = app.test_client().get("/readyz").json
    assert body["failing"] == ["workers"]
    assert body["checks"]["workers"]["detail"].startswith("silent for 30")


def test_readyz_names_redis_when_it_is_down(
    make_config: Callable[..., Config], tmp_path: Path
) -> None:
    stopped = RedisServer(tmp_path / "gone")
    stopped.stop()
    with running_app(make_config(redis_url=stopped.url())) as app:
        response = app.test_client().get("/readyz")
    assert response.status_code == 503
    assert {"redis", "workers", "beat"} <= set(response.json["failing"])
    assert response.json["checks"]["workers"]["detail"] == "unknown: Redis is unreachable"


def test_readyz_names_a_stuck_outbox(app: Flask, team_a: Team, tmp_path: Path) -> None:
    _hear_everyone(app)
    run = finished_run(open_task(team_a.id), None, tmp_path)
    db.session.add(PortalUpload(run_id=run.id, created_at=utcnow() - timedelta(hours=2)))
    db.session.commit()
    body = app.test_client().get("/readyz").json
    assert body["failing"] == ["outbox"]
    assert "waited 2:00" in body["checks"]["outbox"]["detail"]


@pytest.mark.parametrize("ready", [False, True])
def test_status_command_prints_the_same_and_exits_nonzero_when_not_ready(
    app: Flask, ready: bool
) -> None:
    config = app.config["CLOUDSIM"]
    if ready:
        _hear_everyone(app)
    env = {
        "CLOUDSIM_INSTANCE_DIR": str(config.instance_dir),
        "CLOUDSIM_DATABASE_URL": config.database_url,
        "CLOUDSIM_REDIS_URL": config.effective_redis_url,
        "CLOUDSIM_ENCRYPTION_KEYS": ",".join(config.encryption_keys),
        "CLOUDSIM_SECRET_KEY": config.secret_key,
    }
    result = CliRunner().invoke(main, ["status", "--json"], env=env)
    assert result.exit_code == (0 if ready else 1), result.output
    body = json.loads(result.output)
    assert body == app.test_client().get("/readyz").json | {"checks": body["checks"]}
    assert set(body["checks"]) == PARTS
    text = CliRunner().invoke(main, ["status"], env=env).output
    assert ("CloudSim is ready" if ready else "CloudSim is not ready") in text
    assert ("FAIL workers: never heard from" in text) is not ready
