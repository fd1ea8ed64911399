"""CLOUDSIM_LOG_FORMAT=json: one JSON object a line with the ids of what it is about, from the
web app, the job runner, and a real `cloudsim up`'s web server, worker and beat; no secret."""

from __future__ import annotations

import json
import logging
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import requests

from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.jobs.runner import JobContext, Payload, job_kind
from cloudsim.jobs.service import enqueue, run_here
from cloudsim.models import Role
from tests.conftest import PASSWORD, log_in, make_user, running_app, token_for
from tests.monitoring.support import measurable_season
from tests.support.servers import wait_for
from tests.support.up import cloudsim_up


@dataclass(frozen=True)
class AboutRun(Payload):
    """A run the test job is about."""

    run_id: int

    def about(self) -> tuple[str, int]:
        return ("run", self.run_id)


@job_kind("test.logs", payload=AboutRun)
def logging_job(ctx: JobContext, job: AboutRun) -> None:
    """Log a line through Python's logging, as job bodies and the libraries they call do."""
    logging.getLogger("cloudsim.tests").warning("working on run %s", job.run_id)


@pytest.fixture
def restored_logging() -> Iterator[None]:
    """Put the root and `cloudsim` loggers back as they were (JSON logging replaces them)."""
    root, cloudsim = logging.getLogger(), logging.getLogger("cloudsim")
    saved = (list(root.handlers), root.level, list(cloudsim.handlers), cloudsim.propagate)
    yield
    root.handlers[:], cloudsim.handlers[:] = saved[0], saved[2]
    root.setLevel(saved[1])
    cloudsim.propagate = saved[3]


# Not CloudSim's lines: pybullet's C code prints a banner when the simulator's package is
# imported; the private Redis `cloudsim up` starts logs its own way; Celery prints its shutdown
# notice straight to the terminal.
FOREIGN = re.compile(
    r"pybullet build time: .*|\d+:(?:[CMSX]|signal-handler) .*|worker: (Warm|Cold) shutdown .*"
)


def _lines(text: str) -> list[dict[str, Any]]:
    """Parse every line as one JSON object (fails on a line that is not)."""
    return [
        json.loads(line)
        for line in text.splitlines()
        if line.strip() and not FOREIGN.fullmatch(line)
    ]


def test_web_and_job_lines_are_json_with_their_ids_and_no_secret(
    make_config: Callable[..., Config],
    restored_logging: None,
    capfd: pytest.CaptureFixture[str],
) -> None:
    config = make_config(log_format="json", log_level="INFO")
    with running_app(config) as app:
        app.config["WTF_CSRF_ENABLED"] = True
        admin = make_user(Role.ADMIN)
        admin_id = admin.id
        client = app.test_client()
        log_in(client, admin)  # the password, in a form
        headers = {**token_for(admin), "X-Request-ID": "req-from-the-proxy"}
        issued = client.post("/api/v1/tokens", json={"name": "ci"}, headers=headers)
        assert issued.status_code == 201
        assert issued.headers["X-Request-ID"] == "req-from-the-proxy"
        forged = client.get("/healthz", headers={"X-Request-ID": "x" * 65})  # too long: replaced
        assert (
            len(forged.headers["X-Request-ID"]) == 32 and "x" not in forged.headers["X-Request-ID"]
        )
        launched = client.post(
            "/api/v1/constellations",
            json={"name": "json-logs", "kind": "simple", "team_id": None},
            headers=token_for(admin),
        )
        assert launched.status_code in (202, 400, 409), launched.json
        season = measurable_season()
        job = enqueue("test.logs", SYSTEM, AboutRun(run_id=season.run_id))
        db.session.commit()
        run_here(job.id)
    output = capfd.readouterr().err
    lines = _lines(output)
    login = [ln for ln in lines if ln.get("path") == "/login" and ln.get("method") == "POST"]
    assert login and login[0]["status"] == 302 and len(login[0]["request_id"]) == 32
    token_line = next(ln for ln in lines if ln.get("path") == "/api/v1/tokens")
    assert token_line["request_id"] == "req-from-the-proxy"
    assert token_line["user_id"] == admin_id and token_line["status"] == 201
    worked = next(ln for ln in lines if ln["message"] == f"working on run {season.run_id}")
    assert worked["job_id"] == job.id and worked["run_id"] == season.run_id
    for secret in (
        PASSWORD,
        issued.json["token"],
        headers["Authorization"].removeprefix("Bearer "),
        config.secret_key,
        *config.encryption_keys,
    ):
        assert secret not in output


def test_cloudsim_up_logs_json_from_web_worker_and_beat(
    tmp_path: Path, pytestconfig: pytest.Config
) -> None:
    password = "the admin's password, never logged"
    settings = {
        "CLOUDSIM_WEB_WORKERS": "1",
        "CLOUDSIM_ADMIN_PASSWORD": password,
        "CLOUDSIM_LOG_LEVEL": "INFO",
        "CLOUDSIM_LOG_FORMAT": "json",
    }
    with cloudsim_up(tmp_path, pytestconfig.rootpath, **settings) as up:
        base = f"http://{up.address}"
        session = requests.Session()
        # the beat's heartbeat reached a worker and both were heard from (slow to start on a
        # busy 2-core machine)
        wait_for(lambda: session.get(f"{base}/readyz", timeout=60).status_code == 200, 300, "ready")
        page = session.get(f"{base}/login", timeout=60).text
        csrf = re.search(r'name="csrf_token" type="hidden" value="([^"]+)"', page).group(1)  # type: ignore[union-attr]
        data = {"email": "root@example.org", "password": password, "csrf_token": csrf}
        assert session.post(f"{base}/login", data=data, timeout=60).url == f"{base}/"
    assert password not in up.log.read_text()  # the terminal: `cloudsim up`'s own lines, text
    # every service writes its own file, where each of its lines is JSON
    folder = tmp_path / "instance" / "logs"
    text = "\n".join((folder / f"{name}.log").read_text() for name in ("web", "worker", "beat"))
    assert password not in text
    lines = _lines(text)
    loggers = {ln["logger"] for ln in lines}
    assert "cloudsim.access" in loggers  # the web app's request lines
    assert any(name.startswith("gunicorn") for name in loggers)
    assert any(name.startswith("celery.worker") or name == "celery.apps.worker" for name in loggers)
    assert any(name.startswith("celery.beat") for name in loggers)
    assert "py.warnings" in loggers  # Celery's warning about running as root
    login = next(ln for ln in lines if ln.get("path") == "/login" and ln["method"] == "POST")
    assert login["status"] == 302 and login["request_id"]
