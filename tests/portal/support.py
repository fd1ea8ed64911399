"""A small season of runs with their logs stored, their figures read from those logs."""

from __future__ import annotations

import hashlib
import itertools
from datetime import timedelta
from pathlib import Path
from typing import Any

from csrouter.bandwidth_log import read_bandwidth_log

from cloudsim.extensions import db
from cloudsim.models import (
    Constellation,
    ConstellationState,
    Run,
    RunState,
    Task,
    Team,
    TeamInstance,
    utcnow,
)
from cloudsim.models.team_instances import InstanceState
from cloudsim.portal.credentials import upload_token
from cloudsim.portal.plausibility import PROOF_LOGS
from tests.competition.support import open_task, store_log
from tests.support.season import bandwidth_log, score_log

_serial = itertools.count(1)


def scored_run(
    team_id: int,
    tmp: Path,
    *,
    checkpoints: int,
    uplink_bytes: int,
    uplink_cap: int = 8_000_000,
    seconds: int = 30,
    state: RunState = RunState.FINISHED,
) -> Run:
    """Add a run of a fresh task with a score log and a bandwidth log stored, its score and
    bits used read from them (as the stop job does); the caller's session is committed."""
    n = next(_serial)
    start = utcnow() - timedelta(hours=100 - n)
    task = Task(
        team_id=team_id,
        name=f"Portal task {n}",
        world="vrc_task_1",
        run_config=1 + n % 5,
        window_start=start,
        window_stop=start + timedelta(hours=1),
        uplink_bits=uplink_cap,
        downlink_bits=64_000_000,
    )
    db.session.add(task)
    db.session.flush()
    folder = tmp / f"run-{n}"
    folder.mkdir()
    (folder / "score.jsonl").write_text(score_log(checkpoints))
    (folder / "bandwidth.jsonl").write_text(
        bandwidth_log(seconds, uplink_bytes, (uplink_cap, 64_000_000))
    )
    usage = read_bandwidth_log((folder / "bandwidth.jsonl").read_text().splitlines())
    run = Run(
        task_id=task.id,
        team_id=team_id,
        state=state,
        score=checkpoints,
        sim_seconds=10.0 * checkpoints,
        uplink_bits_used=sum(usage["uplink"].bits_per_second),
        downlink_bits_used=sum(usage["downlink"].bits_per_second),
        end_reason="time_limit",
        started_at=start,
        finished_at=start + timedelta(minutes=30),
    )
    db.session.add(run)
    db.session.flush()
    for name in ("score.jsonl", "bandwidth.jsonl"):
        store_log(run, folder / name, name)
    db.session.commit()
    return run


def team_instance(team_id: int, name: str, url: str) -> TeamInstance:
    """Add a ready team instance of the team at url (its constellation a bare row)."""
    constellation = Constellation(name=f"{name}-cloudsim", kind="cloudsim", provider="local")
    db.session.add(constellation)
    db.session.flush()
    instance = TeamInstance(
        name=name,
        team_id=team_id,
        constellation_id=constellation.id,
        state=InstanceState.READY,
        url=url,
    )
    db.session.add(instance)
    db.session.commit()
    return instance


def uploader(
    team: Team, log: bytes, state: str = "finished"
) -> tuple[dict[str, str], dict[str, Any]]:
    """Add an instance of the team; return its upload token and the record of an ended run of
    a fresh task, with two logs of the given bytes."""
    opened = utcnow() - timedelta(hours=1)
    task = open_task(team.id, name="Driving 1", window_start=opened)
    instance = TeamInstance(
        name="ti-a",
        team=team,
        constellation=Constellation(
            name="ti-a", kind="cloudsim", provider="local", state=ConstellationState.READY
        ),
    )
    db.session.add(instance)
    db.session.flush()
    token = {"Authorization": f"Bearer {upload_token(instance)}"}
    started = utcnow() - timedelta(minutes=30)
    declared = {"filename": "", "kind": "state", "size": len(log)}
    record = {
        "team": team.name,
        "task_key": f"m{task.id}",
        "task_name": task.name,
        "world": task.world,
        "run_config": task.run_config,
        "state": state,
        "score": 1,
        "falls": 0,
        "sim_seconds": 600.0,
        "uplink_bits_used": 1000,
        "downlink_bits_used": 1000,
        "uplink_bits": task.uplink_bits,
        "downlink_bits": task.downlink_bits,
        "timeout_s": task.timeout_s,
        "seconds_left": 0.0,
        "started_at": started.isoformat(),
        "finished_at": (started + timedelta(minutes=10)).isoformat(),
        "score_events": [
            {
                "kind": "checkpoint",
                "checkpoint": 1,
                "points": 1,
                "sim_time": 300.0,
                "wall_time": (started + timedelta(minutes=5)).isoformat(),
            }
        ],
        "logs": [
            dict(declared, filename=name, sha256=hashlib.sha256(log).hexdigest())
            for name in ("a.bin", "b.bin")
        ]
        + [  # what a finished run is re-simulated from, declared (empty: stored at once)
            {"filename": name, "kind": "proof", "size": 0, "sha256": hashlib.sha256().hexdigest()}
            for name in PROOF_LOGS
        ],
    }
    db.session.commit()
    return token, record
