"""Live view over SSH on loopback: a real real-time `drcsim serve`, the relay following it with
`drcsim watch` run through a real sshd on 127.0.0.1 (as on a sim machine), an officer's Chromium.

The relay job itself on local hosts (a run's constellation, SSH through its router) is in
tests/competition/test_run_e2e.py; this one needs neither root namespaces nor hosts.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from drcsim.bench import start_server, wait_ready
from flask import Flask, current_app
from playwright.sync_api import Browser, expect

from cloudsim.models import RunState, User
from cloudsim.viewer.live import _Relay, follow_simulator, redis_client
from provisioners.remote.ssh import ConnectPolicy, HostKeys, SSHExecutor, SSHTarget
from tests.provisioners.remote.ssh.conftest import (  # noqa: F401
    client_key,
    make_machine,
    privsep_dir,
    sshd,
    sshd_factory,
)
from tests.provisioners.remote.ssh.sshd_server import SshServer
from tests.viewer.conftest import store_run, wait_for
from tests.viewer.test_viewer_browser import ARTIFACTS
from tests.web.test_browser import live_url, log_in_page, webgl_chromium  # noqa: F401

pytestmark = pytest.mark.browser
DRCSIM = str(Path(sys.executable).with_name("drcsim"))


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


def test_an_officer_watches_a_running_simulator_live(
    app: Flask,
    live_url: str,  # noqa: F811
    webgl_browser: Browser,
    people: dict[str, User | None],
    run_logs: Path,
    simulator: int,
    sshd: SshServer,  # noqa: F811
    make_machine: Callable[..., SSHTarget],  # noqa: F811
) -> None:
    user_a, officer = people["user_a"], people["officer"]
    assert user_a is not None and user_a.team is not None and officer is not None
    run = store_run(user_a.team, run_logs, RunState.RUNNING)
    relay = _Relay(run, redis_client(), current_app.config["CLOUDSIM"])

    def follow() -> None:
        with (
            app.app_context(),
            SSHExecutor(
                HostKeys(),
                log_sink=relay.line,
                connect_policy=ConnectPolicy(deadline=15),
            ) as executor,
        ):
            sim = make_machine(sshd)
            follow_simulator(executor, sim, relay, drcsim=DRCSIM, port=simulator, chunk_s=3)

    follower = threading.Thread(target=follow, daemon=True)
    page = webgl_browser.new_context().new_page()
    log_in_page(page, live_url, officer)
    page.goto(f"{live_url}/runs/{run.id}/view")
    wait_for(page, "window.cloudsimViewer && cloudsimViewer.ready", timeout=60_000)
    expect(page.locator("#viewer-status")).to_contain_text("waiting for the simulator")
    follower.start()  # as the job would: started by a viewer's poll
    wait_for(page, "cloudsimViewer.step !== null", timeout=60_000)
    first = page.evaluate("cloudsimViewer.t")
    wait_for(page, f"cloudsimViewer.t > {first} + 4", timeout=30_000)  # 2nd chunk too
    robot = page.evaluate("cloudsimViewer.robotId()")
    x, y, z = page.evaluate(f"cloudsimViewer.linkPosition({robot}, 0)")
    assert abs(x) < 0.5 and abs(y) < 0.5 and 0.6 < z < 1.2  # standing at the start
    assert "behind the simulator" in page.locator("h1 + p").inner_text()
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    page.locator("#viewer").screenshot(path=str(ARTIFACTS / "viewer-live.png"))
    page.context.close()  # nobody watches any more: the relay stops by itself
    follower.join(timeout=60)
    assert not follower.is_alive() and relay.frames > 40
