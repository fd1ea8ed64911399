"""End to end on a local vrc constellation: schedule, start in Chromium, drive from fc1, end by
timeout, logs with matching checksums, score and leaderboard; refusals; a worker killed mid-run.
"""

from __future__ import annotations

import hashlib
import json
import shlex
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from datetime import datetime, timedelta
from pathlib import Path

import pytest
from celery.contrib.testing.worker import start_worker
from csrouter.bandwidth_log import read_bandwidth_log
from drcsim.rundir import BANDWIDTH_MCAP, MCAP
from drcsim.worlds import document_digest
from flask import Flask
from playwright.sync_api import Browser, Page, expect
from werkzeug.serving import make_server

from cloudsim.auth.policy import SYSTEM
from cloudsim.competition.artifacts import (
    RUN_LOGS,
    LogStore,
    collect_logs,
    remote_sha256,
    run_dir,
)
from cloudsim.competition.jobs import ROUTER_FAULT, machines
from cloudsim.competition.live import refresh_live_runs
from cloudsim.competition.schedule import in_zone
from cloudsim.competition.supervision import supervise_runs
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations import service as constellations
from cloudsim.models import JobState, Role, Run, RunState, Team, User, utcnow
from cloudsim.people import service as people_service
from tests.competition.support import hold_task_2_with_gate_1_near
from tests.conftest import make_user, token_for
from tests.launched_constellations.conftest import finished
from tests.support.mcap_files import validated_topics
from tests.support.servers import wait_for
from tests.support.workers import kill_worker, worker_process
from tests.viewer.conftest import wait_for as wait_in_page
from tests.web.test_browser import log_in_page, webgl_chromium

pytestmark = [pytest.mark.hosts, pytest.mark.browser]
ZONE = "Europe/Berlin"
RUN_SECONDS = 25  # simulated: time to watch it live; gate_1 (moved to 1.5 m) is passed at ~7.5 s


@pytest.fixture
def live_url(constellations_app: Flask) -> Iterator[str]:
    server = make_server("127.0.0.1", 0, constellations_app, threaded=True)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_port}"
    server.shutdown()
    thread.join()


@pytest.fixture
def browser() -> Iterator[Browser]:
    with webgl_chromium() as browser:  # WebGL: an officer watches the run in 3D
        yield browser


def _local(minutes: int) -> str:
    return in_zone(utcnow() + timedelta(minutes=minutes), ZONE).strftime("%Y-%m-%dT%H:%M")


# vrc: ends at its time limit. simple: no router to arm and no field computer (team code runs
# on the practice server); the user stops it from the browser once it has scored.
@pytest.mark.parametrize(
    ("kind", "team_machine", "ending"),
    [("vrc", "fc1", "time_limit"), ("simple", "sim", "stopped")],
)
def test_a_scheduled_run_from_the_browser_to_the_leaderboard(
    constellations_app: Flask,
    constellations_config: Config,
    live_url: str,
    browser: Browser,
    tmp_path: Path,
    pytestconfig: pytest.Config,
    kind: str,
    team_machine: str,
    ending: str,
) -> None:
    timeout_s = RUN_SECONDS if ending == "time_limit" else 4 * RUN_SECONDS
    team_a = people_service.create_team(SYSTEM, "Team A")
    team_b = people_service.create_team(SYSTEM, "Team B")
    officer = make_user(Role.OFFICER)
    user_a, user_b = make_user(Role.USER, team_a), make_user(Role.USER, team_b)
    celery = constellations_app.extensions["celery"]
    with start_worker(celery, pool="threads", concurrency=2, perform_ping_check=False):
        constellation, job = constellations.launch(SYSTEM, name="e2e", kind=kind, provider="local")
        constellation.team_id = team_a.id
        db.session.commit()
        done = finished(job.id)
        assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log[:6000]}"

    # the run is built from the world CloudSim holds (here an updated one), not drcsim's copy
    world = hold_task_2_with_gate_1_near(", as this CloudSim holds it")
    db.session.commit()

    page = browser.new_context().new_page()
    log_in_page(page, live_url, officer)
    page.goto(f"{live_url}/tasks")
    page.get_by_label("Name").fill("Walking, short")
    page.get_by_label("Team", exact=True).select_option(label="Team A")
    page.get_by_label("World").select_option("vrc_task_2")
    page.get_by_label("Time zone").fill(ZONE)
    page.get_by_label("Window opens").fill(_local(-1))
    page.get_by_label("Window closes").fill(_local(30))
    page.get_by_label("Timeout (s)").fill(str(timeout_s))
    page.get_by_label("Uplink cap (bits)").fill("115200")
    page.get_by_role("button", name="Schedule").click()
    expect(page.get_by_text("Scheduled Walking, short for 1 team(s).")).to_be_visible()

    # the simulator keeps running when the worker that started it dies
    process = worker_process(constellations_config, pytestconfig.rootpath)
    try:
        page = browser.new_context().new_page()
        log_in_page(page, live_url, user_a)
        page.goto(f"{live_url}/tasks")
        page.get_by_role("button", name="Start run").click()
        expect(page.locator("#run-state")).not_to_have_text("starting", timeout=120_000)
    finally:
        kill_worker(process)
    run = db.session.scalars(db.select(Run)).one()
    assert run.state == RunState.RUNNING, run.error
    expect(page.locator("#run-state")).to_have_text("running")
    _refusals(constellations_app, team_a, user_a, user_b, run)

    db.session.refresh(run)
    with ExitStack() as reading:
        watching = None
        if kind == "vrc":  # the reader runs before the robot moves, as the beat would
            reading.enter_context(live_reader(constellations_app))
            watching = _open_live_page(browser, live_url, user_a, run)
        with machines(run, constellations_config) as reach:
            controller = (
                "systemd-run --unit=example-controller --collect /opt/drcsim/bin/drcsim "
                f"example-controller --server {shlex.quote(reach.sim_ip)} --world vrc_task_2 "
                "--timeout 120"
            )
            reach.executor.run(reach.by_name[team_machine], controller, timeout=30)
            router_crashed = reach.router is not None
            if router_crashed:  # the router's daemon crashes; systemd restarts it mid-run
                kill = "systemctl kill --signal=KILL csrouter"
                reach.executor.run(reach.router, kill, timeout=30)
        if watching is not None:
            _watch_run_page(watching, live_url, run)

    def beat(done: Callable[[Run], bool]) -> Callable[[], bool]:
        def check() -> bool:
            supervise_runs()  # what the beat does every few seconds
            db.session.expire_all()
            return done(db.session.get(Run, run.id))  # type: ignore[arg-type]

        return check

    with start_worker(celery, pool="threads", concurrency=2, perform_ping_check=False):
        if kind == "vrc":
            _watch_live(browser, live_url, officer, user_a, run)
        if ending == "stopped":
            wait_for(beat(lambda r: r.score >= 1), 120, "the first checkpoint")
            page.goto(f"{live_url}/runs/{run.id}")
            page.get_by_role("button", name="Stop run").click()
            expect(page.get_by_text("Stopping the run.")).to_be_visible()
        if router_crashed:
            wait_for(
                beat(lambda r: (r.error or "").startswith(ROUTER_FAULT)),
                60,
                "the router's fault on the run",
            )
        final = (RunState.FINISHED, RunState.ERROR)
        wait_for(beat(lambda r: r.state in final), 180, f"the run to end ({ending})")
    db.session.refresh(run)
    assert run.state == RunState.FINISHED, run.error  # a recovered router fault is a note
    assert (ROUTER_FAULT in (run.error or "")) == router_crashed
    assert run.end_reason == ending and run.score >= 1, (run.end_reason, run.score)
    if ending == "time_limit":
        assert run.sim_seconds == pytest.approx(RUN_SECONDS, abs=0.01)
    else:
        assert run.sim_seconds < timeout_s and run.stop_reason == "stopped"
    assert run.uplink_bits_used >= 0 and run.active_constellation_id is None

    stored = {a.filename: a for a in run.artifacts}
    handed: dict[str, dict] = {}
    expected = [log for log in RUN_LOGS if kind == "vrc" or log.machine == "sim"]
    made = {BANDWIDTH_MCAP} if kind == "vrc" else set()  # by CloudSim, from the router's log
    assert {log.filename for log in expected} | made == set(stored)
    client = constellations_app.test_client()
    headers = token_for(user_a)
    with machines(run, constellations_config) as reach:
        for artifact in (stored[log.filename] for log in expected):
            source = next(log.machine for log in RUN_LOGS if log.filename == artifact.filename)
            target = reach.by_role()[source]
            on_machine = remote_sha256(
                reach.executor, target, f"{run_dir(run.id)}/{artifact.filename}"
            )
            body = client.get(f"/api/v1/runs/{run.id}/logs/{artifact.id}", headers=headers)
            assert body.status_code == 200
            assert hashlib.sha256(body.data).hexdigest() == artifact.sha256 == on_machine
            if artifact.filename in ("world.json", "meta.json"):
                handed[artifact.filename] = json.loads(body.data)
            if artifact.filename == MCAP:  # opens in robotics tools, message by message
                counts, first, last = validated_topics(body.data)
                assert (first, last) == (0, round(run.sim_seconds * 1e9))
                assert counts["/tf"] == round(run.sim_seconds * 1000) // 10  # one per 10 steps
                assert counts["/score/events"] == len(run.score_events) + 1  # and run_start
    assert document_digest(handed["world.json"]) == document_digest(world)
    assert handed["meta.json"]["world_digest"] == document_digest(world)
    # collecting again copies nothing: every log is stored with the same checksum
    lines: list[str] = []
    with machines(run, constellations_config) as reach:
        again = collect_logs(
            run,
            reach.executor,
            reach.by_role(),
            LogStore(constellations_config),
            tmp_path,
            lines.append,
        )
    assert again == [] and len(lines) == len(expected)
    assert all("stored already" in line for line in lines), lines
    other = client.get(f"/api/v1/runs/{run.id}/logs/{artifact.id}", headers=token_for(user_b))
    assert other.status_code == 404
    checkpoints = [e for e in run.score_events if e.kind == "checkpoint"]
    assert len(checkpoints) == run.score

    board = client.get("/api/v1/leaderboard", headers=headers).json
    assert board[0]["team"] == "Team A" and board[0]["checkpoints"] == run.score
    page.goto(f"{live_url}/runs/{run.id}")
    expect(page.locator("#run-state")).to_have_text("finished")
    if kind == "vrc":  # the router was armed with the task's caps and logged the run
        expect(page.locator("svg[aria-label='Uplink bits used'] .limit")).to_have_count(1)
        store = LogStore(constellations_config)
        usage = read_bandwidth_log(store.lines(stored["bandwidth.jsonl"].location))
        assert usage["uplink"].cap_bits == 115200
        body = client.get(
            f"/api/v1/runs/{run.id}/logs/{stored[BANDWIDTH_MCAP].id}", headers=headers
        )
        counts, first, last = validated_topics(body.data)
        assert counts["/router/bandwidth"] >= 2 * (run.sim_seconds - 2)  # both ways each second
    expect(page.get_by_role("link", name="score.jsonl")).to_be_visible()
    page.goto(f"{live_url}/leaderboard")
    expect(page.locator("tr[data-team='Team A'] .checkpoints")).to_have_text(str(run.score))


@contextmanager
def live_reader(app: Flask) -> Iterator[None]:
    """Run the live reader once a second in a thread, as the beat does in production."""
    stop = threading.Event()

    def loop() -> None:
        with app.app_context():
            while not stop.is_set():
                started = time.monotonic()
                refresh_live_runs()
                db.session.remove()
                stop.wait(max(0.0, 1.0 - (time.monotonic() - started)))  # the beat's period

    thread = threading.Thread(target=loop, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(timeout=60)


# Records, in the page, when the first checkpoint row appeared (the browser's clock is the
# machine's: local hosts share it with the simulator that wrote the event's wall time).
SEEN_CHECKPOINT = """() => {
  window.checkpointSeenAt = null;
  const body = document.getElementById("score-events");
  const look = () => {
    if (window.checkpointSeenAt === null && [...body.rows].some(
        (r) => r.cells[1] && r.cells[1].textContent === "checkpoint")) {
      window.checkpointSeenAt = Date.now() / 1000;
    }
  };
  new MutationObserver(look).observe(body, {childList: true, subtree: true});
  look();
}"""


def _open_live_page(browser: Browser, base: str, user: User, run: Run) -> Page:
    """Open the run's page as its team's member before the robot moves."""
    page = browser.new_context().new_page()
    log_in_page(page, base, user)
    page.goto(f"{base}/runs/{run.id}")
    page.evaluate(SEEN_CHECKPOINT)
    return page


def _watch_run_page(page: Page, base: str, run: Run) -> None:
    """A member sees the run live: time advancing every 2 s, the checkpoint within 2 s of the
    simulator logging it, the bandwidth plot growing, when each machine was last heard."""
    clock = page.locator("#run-time")
    expect(clock).not_to_have_text("0.0", timeout=60_000)  # the reader's first answers
    for _ in range(5):
        before = float(clock.inner_text())
        wait_in_page(
            page, f"Number(document.getElementById('run-time').textContent) > {before}", 2_000
        )
    expect(page.locator("#run-heard li[data-role='sim'] time")).not_to_be_empty()
    expect(page.locator("#run-heard li[data-role='router'] time")).not_to_be_empty()
    expect(page.locator("#run-heard li[data-role='fc1'] time")).not_to_be_empty()
    plot = page.locator("svg[aria-label='Uplink bandwidth'] polyline").first
    expect(plot).to_be_attached(timeout=10_000)  # a flat line at 0 has no height: "hidden"
    points = len((plot.get_attribute("points") or "").split())
    uplink = "document.querySelector(\"svg[aria-label='Uplink bandwidth'] polyline\")"
    wait_in_page(page, f"{uplink}.getAttribute('points').split(' ').length > {points}", 5_000)
    row = page.locator("#score-events tr", has_text="checkpoint").first
    expect(row).to_be_visible(timeout=90_000)
    logged = datetime.fromisoformat(row.locator("td").nth(3).inner_text()).timestamp()
    seen = page.evaluate("window.checkpointSeenAt")
    assert seen is not None and seen - logged <= 2.0, (logged, seen)
    constellation = page.context.new_page()
    constellation.goto(f"{base}/constellations/{run.constellation_id}")
    for name in ("sim", "router", "fc1"):
        expect(constellation.locator(f"tr[data-machine='{name}'] .heard")).not_to_have_text("—")
    page.context.close()


def _watch_live(browser: Browser, base: str, officer: User, user_a: User, run: Run) -> None:
    """An officer watches the running run in 3D, relayed through CloudSim; its team may not."""
    page = browser.new_context().new_page()
    log_in_page(page, base, officer)
    page.goto(f"{base}/runs/{run.id}/view")
    wait_in_page(page, "window.cloudsimViewer && cloudsimViewer.ready", 60_000)
    wait_in_page(page, "cloudsimViewer.step !== null", 60_000)  # frames arrive
    first = page.evaluate("cloudsimViewer.t")
    wait_in_page(page, f"cloudsimViewer.t > {first} + 1")  # and move on
    robot = page.evaluate("cloudsimViewer.robotId()")
    x, y, z = page.evaluate(f"cloudsimViewer.linkPosition({robot}, 0)")
    assert 0.5 < z < 1.2, (x, y, z)  # the pelvis, drawn where a walking robot has it
    page.context.close()
    team = browser.new_context().new_page()
    log_in_page(team, base, user_a)
    answer = team.goto(f"{base}/runs/{run.id}/view")
    assert answer is not None and answer.status == 403  # fairness: no live view of its own run
    team.context.close()


def _refusals(app: Flask, team_a: Team, user_a: User, user_b: User, run: Run) -> None:
    """Starts the server refuses while the run is live: another team, no window, busy."""
    client = app.test_client()
    by_b = client.post(f"/api/v1/tasks/{run.task_id}/runs", json={}, headers=token_for(user_b))
    assert by_b.status_code == 403, by_b.json
    officer = make_user(Role.OFFICER)
    later = client.post(
        "/api/v1/tasks",
        json={
            "name": "Later",
            "world": "vrc_task_1",
            "start": _local(60).replace("T", " "),
            "stop": _local(90).replace("T", " "),
            "time_zone": ZONE,
            "team_ids": [team_a.id],
        },
        headers=token_for(officer),
    ).json[0]
    too_early = client.post(f"/api/v1/tasks/{later['id']}/runs", json={}, headers=token_for(user_a))
    assert too_early.status_code == 403, too_early.json
    now = client.post(
        "/api/v1/tasks",
        json={
            "name": "Now too",
            "world": "vrc_task_1",
            "start": _local(-1).replace("T", " "),
            "stop": _local(30).replace("T", " "),
            "time_zone": ZONE,
            "team_ids": [team_a.id],
        },
        headers=token_for(officer),
    ).json[0]
    busy = client.post(f"/api/v1/tasks/{now['id']}/runs", json={}, headers=token_for(user_a))
    assert busy.status_code == 409 and "busy" in busy.json["message"], busy.json
