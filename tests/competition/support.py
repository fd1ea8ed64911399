"""Competition rows for tests: an open task, a finished run with a stored log."""

from __future__ import annotations

import itertools
from datetime import timedelta
from pathlib import Path
from typing import Any

from drcsim.worlds import shipped_document
from flask import current_app
from sqlalchemy import update

from cloudsim.auth.policy import SYSTEM
from cloudsim.competition.artifacts import LogStore, file_sha256
from cloudsim.extensions import db
from cloudsim.models import (
    Artifact,
    Constellation,
    ConstellationState,
    Run,
    RunState,
    Task,
    utcnow,
)
from cloudsim.worlds.service import update_world

_names = itertools.count(1)
SCORE_LOG = (
    '{"event": "run_start", "score": 0, "sim_time": 0.0, "wall_time": 1795337764.0}\n'
    '{"checkpoint": 1, "event": "checkpoint", "name": "gate", "points": 1, "score": 1, '
    '"sim_time": 5.0, "wall_time": 1795337765.0}\n'
)


def open_task(team_id: int, minutes: int = 30, **fields: object) -> Task:
    """Add a task of the team whose window is open now."""
    now = utcnow()
    values: dict[str, object] = dict(
        team_id=team_id,
        name=f"Task {next(_names)}",
        world="vrc_task_2",
        run_config=1,
        window_start=now - timedelta(minutes=1),
        window_stop=now + timedelta(minutes=minutes),
        uplink_bits=1_000_000,
        downlink_bits=8_000_000,
    )
    values.update(fields)
    task = Task(**values)
    db.session.add(task)
    db.session.commit()
    return task


def finished_run(task: Task, constellation_id: int | None, tmp: Path, score: int = 1) -> Run:
    """Add a finished run of the task with its score log stored as an artifact."""
    run = Run(
        task_id=task.id,
        team_id=task.team_id,
        constellation_id=constellation_id,
        state=RunState.FINISHED,
        score=score,
        end_reason="time_limit",
        finished_at=utcnow(),
    )
    db.session.add(run)
    db.session.flush()
    path = tmp / f"score-{run.id}.jsonl"
    path.write_text(SCORE_LOG)
    store_log(run, path, "score.jsonl")
    db.session.commit()
    return run


def store_log(run: Run, path: Path, filename: str) -> Artifact:
    """Put a file into the log store as one of the run's logs (the caller commits)."""
    store = LogStore(current_app.config["CLOUDSIM"])
    name = store.object_name(run.id, filename)
    store.put(path, name)
    artifact = Artifact(
        run_id=run.id,
        kind=filename.split(".")[0],
        filename=filename,
        location=name,
        size=path.stat().st_size,
        sha256=file_sha256(path),
    )
    db.session.add(artifact)
    return artifact


def ready_constellation(constellation_id: int) -> None:
    """Make the constellation ready and free again (whatever earlier visits did to it)."""
    db.session.execute(
        update(Run)
        .where(Run.active_constellation_id.is_not(None))
        .values(active_constellation_id=None, state=RunState.ERROR)
    )
    db.session.execute(
        update(Constellation)
        .where(Constellation.id == constellation_id)
        .values(state=ConstellationState.READY)
    )
    db.session.commit()


def hold_task_2_with_gate_1_near(title_suffix: str = "") -> dict[str, Any]:
    """Make the world CloudSim holds for vrc_task_2 an updated one with gate_1 at 1.5 m
    instead of 4, and return it: the example controller passes it at ~7.5 s simulated, not
    ~16 s, so a run that must score is short."""
    world = shipped_document("vrc_task_2")
    world["title"] += title_suffix
    next(o for o in world["objects"] if o["id"] == "gate_1")["pose"] = [1.5, 0.0, 0.0]
    update_world(SYSTEM, world)
    return world
