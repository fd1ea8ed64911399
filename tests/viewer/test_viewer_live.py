"""Live view on loopback: a real real-time `drcsim serve`, the relay fed by a real `drcsim watch`
(started here as a process instead of over SSH on a sim machine), an officer's Chromium.

The whole path on local hosts (the relay job, SSH to sim) is in
tests/competition/test_run_e2e.py; this one runs without root and without hosts.
"""

from __future__ import annotations

import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
from drcsim.bench import start_server, wait_ready
from flask import Flask, current_app
from playwright.sync_api import Browser

from cloudsim.models import RunState, User
from cloudsim.viewer.live import _Relay, _RelayDone, redis_client
from tests.viewer.conftest import store_run
from tests.web.test_browser import live_url, log_in_page, webgl_chromium  # noqa: F401

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def webgl_browser() -> Iterator[Browser]:
    with webgl_chromium() as browser:
        yield browser


@pytest.fixture
def simulator(tmp_path: Path) -> Iterator[int]:
    """A real-time drcsim server on loopback; stopped by PID afterwards."""
    process, port = start_server("vrc_task_2", "1", [], stderr=tmp_path / "server.log")
    try:
        wait_ready(port, process)
        yield port
    finally:
        process.terminate()
        process.wait(timeout=30)


def _relay(app: Flask, relay: _Relay, watcher: subprocess.Popen[str]) -> None:
    """Feed the watcher's lines to the relay, as the relay job's SSH sink does."""
    assert watcher.stdout is not None
    with app.app_context():
        for line in watcher.stdout:
            try:
                relay.line("sim", line.rstrip("\n"))
            except _RelayDone:
                continue  # nobody watching yet: the job would stop; here the test decides


def test_an_officer_watches_a_running_simulator_live(
    app: Flask,
    live_url: str,  # noqa: F811
    webgl_browser: Browser,
    people: dict[str, User | None],
    run_logs: Path,
    simulator: int,
) -> None:
    user_a, officer = people["user_a"], people["officer"]
    assert user_a is not None and user_a.team is not None and officer is not None
    run = store_run(user_a.team, run_logs, RunState.RUNNING)
    relay = _Relay(run, redis_client(), current_app.config["CLOUDSIM"])
    watch = [sys.executable, "-m", "drcsim.cli", "watch", "--server", "127.0.0.1"]
    watcher = subprocess.Popen(
        [*watch, "--port", str(simulator), "--rate", "10", "--seconds", "90"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    feeder = threading.Thread(target=_relay, args=(app, relay, watcher), daemon=True)
    feeder.start()
    try:
        page = webgl_browser.new_context().new_page()
        log_in_page(page, live_url, officer)
        page.goto(f"{live_url}/runs/{run.id}/view")
        page.wait_for_function("window.cloudsimViewer && cloudsimViewer.ready", timeout=60_000)
        page.wait_for_function("cloudsimViewer.step !== null", timeout=60_000)
        first = page.evaluate("cloudsimViewer.t")
        page.wait_for_function(f"cloudsimViewer.t > {first} + 1", timeout=30_000)
        robot = page.evaluate("cloudsimViewer.robotId()")
        x, y, z = page.evaluate(f"cloudsimViewer.linkPosition({robot}, 0)")
        assert abs(x) < 0.5 and abs(y) < 0.5 and 0.6 < z < 1.2  # standing at the start
        assert "behind the simulator" in page.locator("h1 + p").inner_text()
        page.context.close()
    finally:
        watcher.terminate()
        watcher.wait(timeout=30)
        feeder.join(timeout=30)
        assert watcher.stdout is not None
        watcher.stdout.close()
    assert relay.frames > 10
