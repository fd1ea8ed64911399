"""Workers killed at four steps of a run's start and four of its stop: the run is metered exactly.

One vrc constellation on local hosts, several short runs on it. For each run the worker dies
(SIGKILL, worker and pool) right after one step of `run.start` and, later, right after one
step of `run.stop`; another worker resumes each job. After each run, the bandwidth log the
run keeps has one line a second per direction from the simulator's start to its end, the
router armed the run once (its counters never restarted) with the task's caps on every line,
and current-run.json told the field computers when the simulator really started.
"""

from __future__ import annotations

import json
import os
import shlex
import subprocess
from collections.abc import Callable, Iterator
from datetime import datetime

import pytest
from celery.contrib.testing.worker import start_worker
from drcsim.rundir import read_run_span
from flask import Flask

from cloudsim.auth.policy import SYSTEM
from cloudsim.competition import runs
from cloudsim.competition.artifacts import LogStore, artifact_for
from cloudsim.competition.current_run import CURRENT_RUN
from cloudsim.competition.jobs import machines
from cloudsim.competition.supervision import supervise_runs
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.jobs.service import sweep_jobs
from cloudsim.launched_constellations import service as constellations
from cloudsim.models import Job, JobState, Role, Run, RunState
from cloudsim.people import service as people_service
from constellations.plans.router import CSROUTER_COMMAND
from tests.competition.support import open_task
from tests.conftest import make_user, running_app
from tests.launched_constellations.conftest import (
    destroy_everything,
    finished,
    hosts_config,
)
from tests.support.servers import wait_for
from tests.support.workers import crash_worker

pytestmark = pytest.mark.hosts
PREFIX = f"cm{os.getpid() % 100000}"
RUN_SECONDS = 12  # simulated, at real time
UPLINK_BITS, DOWNLINK_BITS = 400_000, 4_000_000
# (start step, stop step) the worker dies right after, one pair a run: every step of both
CRASHES = [
    ("claimed", "claimed"),
    ("router", "simulator"),
    ("simulator", "router"),
    ("announce", "bandwidth"),
]


@pytest.fixture
def metering_config(make_config: Callable[..., Config]) -> Config:
    return hosts_config(make_config, PREFIX, 223)


@pytest.fixture
def metering_app(metering_config: Config) -> Iterator[Flask]:
    with running_app(metering_config) as app:
        try:
            yield app
        finally:
            destroy_everything(metering_config)


def _resume(app: Flask, job_id: str) -> Job:
    """Let another worker pick up the dead worker's job once its lease runs out."""
    with start_worker(
        app.extensions["celery"], pool="solo", perform_ping_check=False, loglevel="WARNING"
    ):
        wait_for(lambda: sweep_jobs() > 0, 60, "the dead worker's lease to expire")
        return finished(job_id, 300)


def _died(process: subprocess.Popen[bytes], where: str) -> None:
    try:
        process.wait(timeout=180)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
        pytest.fail(f"the worker never reached {where}")


def _job(run: Run, kind: str) -> Job:
    db.session.expire_all()
    return db.session.scalars(
        db.select(Job).where(Job.kind == kind, Job.target_type == "run", Job.target_id == run.id)
    ).one()


@pytest.mark.timeout(2400)  # a launch and four runs, each job killed once and resumed
def test_killed_workers_leave_no_second_of_a_run_unmetered(
    metering_app: Flask, metering_config: Config, pytestconfig: pytest.Config
) -> None:
    team = people_service.create_team(SYSTEM, "Team M")
    officer = make_user(Role.OFFICER)
    celery = metering_app.extensions["celery"]
    with start_worker(celery, pool="threads", concurrency=2, perform_ping_check=False):
        constellation, job = constellations.launch(
            SYSTEM, name="meter", kind="vrc", provider="local"
        )
        constellation.team_id = team.id
        db.session.commit()
        done = finished(job.id)
        assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log[:6000]}"

    for start_step, stop_step in CRASHES:
        task = open_task(
            team.id,
            timeout_s=RUN_SECONDS,
            uplink_bits=UPLINK_BITS,
            downlink_bits=DOWNLINK_BITS,
            latency_ms=100,
        )
        where = f"run.start:{start_step}"
        process = crash_worker(metering_config, pytestconfig.rootpath, where)
        run = runs.start_run(officer, task.id)
        db.session.commit()  # sends the start job
        _died(process, where)
        started = _resume(metering_app, _job(run, "run.start").id)
        assert started.state == JobState.SUCCEEDED, f"{where}: {started.error}\n{started.log}"
        assert started.attempts == 2, where

        where = f"run.stop:{stop_step}"
        process = crash_worker(metering_config, pytestconfig.rootpath, where)

        def stopping(run_id: int = run.id) -> bool:
            supervise_runs()  # the beat: it sees the simulator's time limit and stops the run
            db.session.expire_all()
            return db.session.get(Run, run_id).state != RunState.RUNNING  # type: ignore[union-attr]

        wait_for(stopping, 120, f"run {run.id} to reach its time limit")
        _died(process, where)
        stopped = _resume(metering_app, _job(run, "run.stop").id)
        assert stopped.state == JobState.SUCCEEDED, f"{where}: {stopped.error}\n{stopped.log}"
        db.session.expire_all()
        run = db.session.get(Run, run.id)  # type: ignore[assignment]
        assert run.state == RunState.FINISHED, f"{start_step}/{stop_step}: {run.error}"
        assert run.end_reason == "time_limit", (start_step, stop_step, run.end_reason)
        _check_metering(metering_config, run, f"{start_step}/{stop_step}")


def _check_metering(config: Config, run: Run, crashes: str) -> None:
    store = LogStore(config)
    score, bandwidth = artifact_for(run, "score.jsonl"), artifact_for(run, "bandwidth.jsonl")
    assert score is not None and bandwidth is not None, crashes
    sim_start, sim_end = read_run_span(store.lines(score.location))
    assert sim_start is not None and sim_end is not None, crashes
    records = [json.loads(line) for line in store.lines(bandwidth.location) if line.strip()]
    events = [r.get("event") for r in records if "event" in r]
    assert events == ["armed", "run_span"], (crashes, events)
    assert records[0]["caps_bits"] == {"uplink": UPLINK_BITS, "downlink": DOWNLINK_BITS}
    for direction in ("uplink", "downlink"):
        lines = [r for r in records if r.get("direction") == direction]
        seconds = [r["second"] for r in lines]
        # one line a second, no gap, no restart: the router's own numbering runs on too
        assert seconds == list(range(1, len(lines) + 1)), (crashes, direction, seconds)
        router_seconds = [r["router_second"] for r in lines]
        assert router_seconds == list(range(router_seconds[0], router_seconds[-1] + 1)), crashes
        cumulative = [r["cumulative_bytes"] for r in lines]
        assert cumulative == sorted(cumulative), (crashes, direction)
        # capped throughout
        assert all(r["cap_remaining_bits"] is not None for r in lines), (crashes, direction)
        # from the simulator's start to its end: the first line holds the start, the last the end
        first = datetime.fromisoformat(lines[0]["time"]).timestamp()
        last = datetime.fromisoformat(lines[-1]["time"]).timestamp()
        assert first - 1 <= sim_start < first, (crashes, direction, first, sim_start)
        assert last - 1 < sim_end <= last, (crashes, direction, last, sim_end)
    with machines(run, config) as reach:
        router = reach.router
        assert router is not None
        armed = shlex.quote(f'"event":"armed","run_id":"run-{run.id}"')
        raw = reach.executor.run(
            router,
            f"cat $({CSROUTER_COMMAND} log-path)* | grep -c {armed} || true",
            timeout=30,
        ).stdout.strip()
        assert raw == "1", f"{crashes}: the router armed run {run.id} {raw} times"
        announced = reach.executor.run(
            reach.field_computers[0],
            f"test -f {CURRENT_RUN} && echo present || echo gone",
            timeout=30,
        ).stdout.strip()
        assert announced == "gone", crashes  # withdrawn by the stop
    assert run.running_at is not None
    # what current-run.json said: when the simulator started, not when a resumed job came
    running_at = run.running_at.timestamp()
    assert sim_start - 60 < running_at <= sim_start + 1, (crashes, run.running_at, sim_start)
    uplink = [r for r in records if r.get("direction") == "uplink"]
    assert run.uplink_bits_used == 8 * uplink[-1]["cumulative_bytes"], crashes
