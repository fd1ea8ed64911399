"""`cloudsim up` brings the whole system up, serves the app, runs jobs, and stops cleanly."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import requests

from tests.support.servers import free_port, wait_for


def _children(pid: int) -> list[int]:
    children = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    return [int(c) for c in children]


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0]
    except FileNotFoundError:
        return False
    return state != "Z"


def _start(env: dict[str, str], log: Path, root: Path) -> subprocess.Popen[bytes]:
    with log.open("wb") as out:
        return subprocess.Popen(
            [sys.executable, "-m", "cloudsim.cli", "up"],
            env=env,
            cwd=root,
            stdout=out,
            stderr=subprocess.STDOUT,
        )


def _stop(process: subprocess.Popen[bytes]) -> list[int]:
    children = _children(process.pid)
    process.send_signal(signal.SIGINT)
    assert process.wait(60) == 0
    return children


def test_up_serves_runs_jobs_and_stops_everything(
    tmp_path: Path, pytestconfig: pytest.Config
) -> None:
    web, redis_port = free_port(), free_port()
    env = dict(
        os.environ,
        CLOUDSIM_INSTANCE_DIR=str(tmp_path / "instance"),
        CLOUDSIM_BIND=f"127.0.0.1:{web}",
        CLOUDSIM_REDIS_PORT=str(redis_port),
        CLOUDSIM_WEB_WORKERS="1",
        CLOUDSIM_WORKER_CONCURRENCY="1",
        CLOUDSIM_ADMIN_EMAIL="root@example.org",
        CLOUDSIM_LOG_LEVEL="WARNING",
    )
    env.pop("CLOUDSIM_REDIS_URL", None)
    env.pop("CLOUDSIM_ADMIN_PASSWORD", None)
    log = tmp_path / "up.log"
    process = _start(env, log, pytestconfig.rootpath)
    try:
        wait_for(lambda: "CloudSim is running at" in log.read_text(), 90, "cloudsim up")
        wait_for(lambda: log.read_text().endswith("=\n"), 10, "the framed summary")
        output = log.read_text()
        # what a person needs comes last: the address, then the admin and the password
        *_, rule, running, logs, admin, secret, closing = output.splitlines()
        assert rule == closing and set(rule) == {"="}
        assert running.startswith(f"CloudSim is running at http://127.0.0.1:{web}/")
        assert logs == f"services' logs: {tmp_path / 'instance' / 'logs'}/"
        assert admin == "created the first admin: root@example.org"
        password = re.fullmatch(r"  password \(shown once\): (\S+)", secret).group(1)  # type: ignore[union-attr]
        base = f"http://127.0.0.1:{web}"
        session = requests.Session()
        page = session.get(f"{base}/login", timeout=10).text
        token = re.search(r'name="csrf_token" type="hidden" value="([^"]+)"', page).group(1)  # type: ignore[union-attr]
        login = session.post(
            f"{base}/login",
            data={"email": "root@example.org", "password": password, "csrf_token": token},
            timeout=10,
        )
        assert login.url == f"{base}/" and "Admin dashboard" in login.text
        jobs_page = session.get(f"{base}/jobs", timeout=10).text
        token = re.search(r'name="csrf_token" type="hidden" value="([^"]+)"', jobs_page).group(1)  # type: ignore[union-attr]
        started = session.post(f"{base}/jobs/diagnostics", data={"csrf_token": token}, timeout=10)
        job_id = started.url.rsplit("/", 1)[-1]

        def succeeded() -> bool:
            state = session.get(f"{base}/jobs/{job_id}/progress", timeout=10).json()["state"]
            assert state != "failed"
            return state == "succeeded"

        wait_for(succeeded, 60, "the diagnostics job on the worker")
    finally:
        children = _stop(process)
    assert len(children) == 4  # redis, worker, beat, web
    assert not [pid for pid in children if _alive(pid)]
    output = log.read_text()
    assert output.count(password) == 1  # shown once, and no service printed it
    # the services' output is in their own files, not on the terminal
    assert "GET /login" in (tmp_path / "instance" / "logs" / "web.log").read_text()
    assert "GET /login" not in output

    again = _start(
        env, tmp_path / "again.log", pytestconfig.rootpath
    )  # a second start: same data, no new admin
    try:
        wait_for(
            lambda: "CloudSim is running at" in (tmp_path / "again.log").read_text(),
            90,
            "cloudsim up, again",
        )
    finally:
        _stop(again)
    again_output = (tmp_path / "again.log").read_text()
    assert "created the first admin" not in again_output
    assert "log in as root@example.org; forgot the password? cloudsim user update" in again_output
