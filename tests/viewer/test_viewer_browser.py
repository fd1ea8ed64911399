"""The 3D viewer in a real headless Chromium (software WebGL): a team replays its finished run."""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import urlsplit

import pytest
from drcsim.viewer import world_scene
from flask import Flask
from playwright.sync_api import Browser, expect

from cloudsim.extensions import db
from cloudsim.models import Run, User
from tests.competition.support import store_log
from tests.viewer.conftest import logged_pelvis, store_run, wait_for
from tests.web.test_browser import live_url, log_in_page, webgl_chromium  # noqa: F401

pytestmark = pytest.mark.browser
ARTIFACTS = Path(os.environ.get("CLOUDSIM_TEST_ARTIFACTS", "build/test-artifacts"))


@pytest.fixture(scope="module")
def webgl_browser() -> Iterator[Browser]:
    with webgl_chromium() as browser:
        yield browser


def _add_bandwidth_log(run: Run, tmp_path: Path) -> None:
    lines = [{"event": "armed", "time": "2026-06-17T09:00:00+00:00", "caps_bits": {}}]
    for second in range(1, 11):
        for direction in ("uplink", "downlink"):
            lines.append({"direction": direction, "second": second, "bytes": 1000 * second})
    path = tmp_path / "bandwidth.jsonl"
    path.write_text("".join(json.dumps(line) + "\n" for line in lines))
    store_log(run, path, "bandwidth.jsonl")
    db.session.commit()


def test_a_team_replays_its_run_where_the_state_log_says(
    app: Flask,
    live_url: str,  # noqa: F811
    webgl_browser: Browser,
    people: dict[str, User | None],
    run_logs: Path,
    tmp_path: Path,
) -> None:
    user = people["user_a"]
    assert user is not None and user.team is not None
    run = store_run(user.team, run_logs)
    _add_bandwidth_log(run, tmp_path)
    context = webgl_browser.new_context(viewport={"width": 1280, "height": 1000})
    page = context.new_page()
    hosts: set[str] = set()
    context.on("request", lambda request: hosts.add(urlsplit(request.url).netloc))
    log_in_page(page, live_url, user)
    run_page = context.new_page()  # the run's page stays open in another tab
    run_page.goto(f"{live_url}/runs/{run.id}")
    page.goto(f"{live_url}/runs/{run.id}")
    page.get_by_role("link", name="Replay in 3D").click()
    wait_for(page, "window.cloudsimViewer && window.cloudsimViewer.ready", timeout=60_000)
    assert page.evaluate("cloudsimViewer.error") is None

    # the scene holds the robot and every object of the world
    world = world_scene("vrc_task_2", "1")
    assert page.evaluate("cloudsimViewer.bodies") == len(world["bodies"]) > 20
    robot = page.evaluate("cloudsimViewer.robotId()")
    assert robot == world["roles"]["robot"]

    # at a given time the robot's pelvis is drawn where the state log has it
    page.evaluate("cloudsimViewer.seek(9.0)")
    step = page.evaluate("cloudsimViewer.step")
    assert step == 9000
    drawn = page.evaluate(f"cloudsimViewer.linkPosition({robot}, 0)")
    logged = logged_pelvis(run_logs, step)
    assert max(abs(a - b) for a, b in zip(drawn, logged, strict=True)) < 1e-3, (drawn, logged)
    assert logged[0] > 1.5  # it has walked: a test that could not tell poses apart would pass

    # a score event on the timeline jumps there; the bandwidth charts mark the same second
    mark = page.locator(".viewer-mark.checkpoint").first
    when = float(mark.get_attribute("data-t") or "nan")
    mark.click()
    wait_for(page, f"Math.abs(cloudsimViewer.t - {when}) < 0.04")
    markers = page.locator("#viewer-bandwidth line.replay-mark")
    second = str(int(page.evaluate("cloudsimViewer.t")))
    expect(markers.first).to_have_attribute("data-second", second)
    # and so do the charts on the run's page in the other tab
    on_run_page = run_page.locator("section.charts line.replay-mark")
    expect(on_run_page).to_have_count(4)
    expect(on_run_page.first).to_have_attribute("data-second", second)

    # play at 8x: a real second moves the replay several simulated seconds
    page.evaluate("cloudsimViewer.seek(0)")
    page.get_by_label("Speed").select_option("8")
    page.get_by_role("button", name="Play").click()
    wait_for(page, "cloudsimViewer.t > 3", timeout=5_000)
    page.get_by_role("button", name="Pause").click()

    page.evaluate("cloudsimViewer.seek(5.5)")
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    page.locator("#viewer").screenshot(path=str(ARTIFACTS / "viewer-replay.png"))
    assert hosts == {urlsplit(live_url).netloc}, f"requests to other hosts: {hosts}"
