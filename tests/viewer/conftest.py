"""A finished run with real simulator logs (a short walk through gate_1), stored like any run's."""

from __future__ import annotations

import struct
import time
from pathlib import Path

import pytest
from drcsim.engine import RunOptions, Simulation
from drcsim.runlog import read_states
from flask import current_app
from playwright.sync_api import Page

from cloudsim.competition.artifacts import LogStore
from cloudsim.competition.jobs import score_run
from cloudsim.extensions import db
from cloudsim.models import Run, RunState, Team, utcnow
from tests.competition.support import open_task, store_log

RUN_S = 19.5  # simulated: the walker takes the robot through gate_1 (x = 4 m) at about 15.5 s,
# credited once it stayed up 3 s more (drcsim.scoring.STEADY_S)
LOGS = ("meta.json", "state.msgpack", "score.jsonl", "commands.jsonl", "final.json")


@pytest.fixture(scope="session")
def run_logs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Return the log folder of a real 9 s run of vrc_task_2 (made once per session)."""
    folder = tmp_path_factory.mktemp("viewer") / "run"
    sim = Simulation("vrc_task_2", "1", RunOptions(log_dir=folder, time_limit_s=RUN_S))
    sim.apply_command({"op": "behaviour", "name": "walk", "pose": [6.0, 0.0, 0.0]})
    while not sim.ended:
        sim.step(1000)
    sim.close()
    return folder


def store_run(team: Team, folder: Path, state: RunState = RunState.FINISHED) -> Run:
    """Add a run of the team whose logs are the ones in `folder`, scored from them."""
    task = open_task(team.id)
    run = Run(task_id=task.id, team_id=team.id, state=state, finished_at=utcnow())
    db.session.add(run)
    db.session.flush()
    for filename in LOGS:
        store_log(run, folder / filename, filename)
    db.session.commit()
    score_run(run, LogStore(current_app.config["CLOUDSIM"]))
    run.state = state
    db.session.commit()
    return run


def logged_pelvis(folder: Path, step: int) -> tuple[float, float, float]:
    """Return the robot's pelvis position the state log holds for a step (float32, metres)."""
    for record in read_states(folder):
        if record["step"] == step:
            x, y, z = struct.unpack_from("<3f", record["state32"])
            return x, y, z
    raise AssertionError(f"no state record for step {step}")


def wait_for(page: Page, expression: str, timeout: float = 30_000) -> None:
    """Await a condition by polling page.evaluate: the pages' CSP forbids the eval that
    Playwright's wait_for_function runs inside the page."""
    deadline = time.monotonic() + timeout / 1000
    while not page.evaluate(expression):
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {expression}")
        page.wait_for_timeout(50)
