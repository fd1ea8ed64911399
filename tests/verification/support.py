"""Real short drcsim runs, logged as the simulator logs a served run, and their rows."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

from drcsim.engine import RunOptions, Simulation
from drcsim.protocol import check_command
from drcsim.rundir import COMMANDS, FILES, WORLD
from flask import current_app

from cloudsim.competition.artifacts import LogStore
from cloudsim.competition.jobs import score_run
from cloudsim.extensions import db
from cloudsim.models import Run, RunState, Task, World, utcnow
from tests.competition.support import store_log

WORLD_NAME = "vrc_task_2"
TIMEOUT_S = 60
# What team code sends, at which physics step: a walk, an arm moved while walking, a stand.
SENT = (
    (0, {"op": "behaviour", "name": "walk", "pose": [1.0, 0.0, 0.0]}),
    (700, {"op": "joints", "position": {"r_arm_shz": 0.4}, "gains": {"r_arm_shz": [500, 5, 20]}}),
    (1800, {"op": "behaviour", "name": "stand"}),
)
EDITED = ('"r_arm_shz": 0.4}', '"r_arm_shz": 0.41}')  # one command's value, changed


def simulate(folder: Path, world: dict[str, Any], seconds: float = 2.5) -> dict[str, Any]:
    """Run vrc_task_2 for `seconds` simulated seconds as a served run does (its logs in
    `folder`), closed from outside at the end as CloudSim's stop closes it."""
    sim = Simulation(
        WORLD_NAME, 1, RunOptions(log_dir=folder, world_document=world, time_limit_s=TIMEOUT_S)
    )
    try:
        for step, command in SENT:
            sim.step(step - sim.step_count)
            assert sim.apply_command(check_command(command))["ok"]
        sim.step(int(seconds * 1000) - sim.step_count)
    finally:
        sim.close()
    return {name: (folder / name).read_bytes() for name in (*FILES, WORLD)}


def edit_command(logs: dict[str, bytes]) -> dict[str, bytes]:
    """Return the logs with one command's value changed in the command log."""
    edited = logs[COMMANDS].decode().replace(*EDITED)
    assert edited != logs[COMMANDS].decode(), "the command to edit is in the log"
    return {**logs, COMMANDS: edited.encode()}


def held_world() -> dict[str, Any]:
    """Return the world document this CloudSim holds for the runs' world."""
    row = db.session.query(World).filter_by(name=WORLD_NAME).one()
    return dict(row.document)


def master_run(task: Task, logs: dict[str, bytes], tmp: Path) -> Run:
    """Add a run finished on this CloudSim with these logs stored and scored from them, as
    its stop job leaves it (committed)."""
    run = Run(
        task_id=task.id,
        team_id=task.team_id,
        state=RunState.FINISHED,
        stop_reason="stopped",
        started_at=utcnow(),
        finished_at=utcnow(),
    )
    db.session.add(run)
    db.session.flush()
    folder = tmp / f"run-{run.id}"
    folder.mkdir(parents=True)
    for name, content in logs.items():
        (folder / name).write_bytes(content)
        store_log(run, folder / name, name)
    db.session.flush()
    db.session.refresh(run)
    score_run(run, LogStore(current_app.config["CLOUDSIM"]))  # as the stop job scores it
    db.session.commit()
    return run


def sha256(content: bytes) -> str:
    """Return a log's SHA-256 as the upload API declares it."""
    return hashlib.sha256(content).hexdigest()
