"""Runs uploaded through the documented API with a real run's logs are verified as soon as their
logs are in: the honest record verifies, a record claiming more than its logs replay is held."""

from __future__ import annotations

import copy
from collections.abc import Iterator
from datetime import timedelta
from pathlib import Path
from typing import Any

import pytest
from celery.contrib.testing.worker import start_worker
from drcsim.rundir import SCORE, read_score_log
from drcsim.worlds import shipped_document
from flask import Flask
from sqlalchemy import select

from cloudsim.extensions import db
from cloudsim.models import Job, JobState, Role, utcnow
from cloudsim.portal.credentials import upload_token
from cloudsim.verification import service
from tests.conftest import make_user, token_for
from tests.portal.support import team_instance
from tests.support.workers import job_finished
from tests.verification.support import TIMEOUT_S, WORLD_NAME, sha256, simulate

REPLAY_WAIT_S = 600


@pytest.fixture(scope="module")
def real_logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    return simulate(tmp_path_factory.mktemp("run"), shipped_document(WORLD_NAME))


@pytest.fixture
def workers(app: Flask) -> Iterator[None]:
    with start_worker(
        app.extensions["celery"],
        pool="threads",
        concurrency=2,
        perform_ping_check=False,
        loglevel="WARNING",
        shutdown_timeout=30,
    ):
        yield


def _record(task: dict[str, Any], logs: dict[str, bytes]) -> dict[str, Any]:
    """The record a team instance sends for a run with these logs (times as it saw them)."""
    score = read_score_log(logs[SCORE].decode().splitlines())
    finished = utcnow() - timedelta(seconds=30)
    started = finished - timedelta(seconds=20)
    return {
        "team": "Team A",
        "task_key": f"m{task['id']}",
        "task_name": task["name"],
        "world": WORLD_NAME,
        "run_config": 1,
        "state": "finished",
        "end_reason": "stopped",
        "score": score.score,
        "falls": score.falls,
        "sim_seconds": score.sim_seconds,
        "uplink_bits_used": 0,
        "downlink_bits_used": 0,
        "uplink_bits": task["uplink_bits"],
        "downlink_bits": task["downlink_bits"],
        "timeout_s": TIMEOUT_S,
        "seconds_left": TIMEOUT_S - score.sim_seconds,
        "started_at": started.isoformat(),
        "finished_at": finished.isoformat(),
        "score_events": [
            {
                "kind": event.kind,
                "checkpoint": event.checkpoint,
                "points": event.points,
                "sim_time": event.sim_time,
                "wall_time": (started + timedelta(seconds=1 + event.sim_time)).isoformat(),
                "description": event.description,
            }
            for event in score.events
        ],
        "logs": [
            {
                "filename": name,
                "kind": name.split(".")[0],
                "size": len(body),
                "sha256": sha256(body),
            }
            for name, body in logs.items()
        ],
    }


def _upload(
    client: Any, headers: dict[str, str], remote_id: int, record: dict[str, Any], logs: Any
) -> int:
    base = f"/api/v1/portal/ingest/runs/{remote_id}"
    sent = client.put(base, json=record, headers=headers)
    assert sent.status_code == 200, sent.json
    for name, body in logs.items():
        if body:
            piece = client.put(
                f"{base}/logs/{name}?offset=0",
                data=body,
                headers={**headers, "Content-Type": "application/octet-stream"},
            )
            assert piece.status_code == 200 and piece.json["complete"], piece.json
    done = client.post(f"{base}/complete", headers=headers)
    assert done.status_code == 200 and done.json["complete"], done.json
    return int(done.json["run_id"])


def test_uploaded_runs_are_verified_from_their_logs(
    app: Flask, workers: None, real_logs: dict[str, bytes], tmp_path: Path
) -> None:
    client = app.test_client()
    officer = token_for(make_user(Role.OFFICER))
    team = client.post("/api/v1/teams", json={"name": "Team A"}, headers=officer).json
    now = utcnow()
    body = {
        "name": "Walking",
        "world": WORLD_NAME,
        "run_config": 1,
        "start": (now - timedelta(hours=1)).strftime("%Y-%m-%d %H:%M"),
        "stop": (now + timedelta(hours=1)).strftime("%Y-%m-%d %H:%M"),
        "time_zone": "UTC",
        "timeout_s": TIMEOUT_S,
        "uplink_bits": 115_200,
        "downlink_bits": 59_000_000,
        "team_ids": [team["id"]],
    }
    tasks = client.post("/api/v1/tasks", json=body, headers=officer)
    second = client.post("/api/v1/tasks", json={**body, "name": "Walking again"}, headers=officer)
    assert tasks.status_code == second.status_code == 201, (tasks.json, second.json)
    # the instance as a row: deploying it for real is the team instances' tests' business
    instance = team_instance(team["id"], "ti-a", "https://127.0.0.1:1/")
    headers = {"Authorization": f"Bearer {upload_token(instance)}"}
    db.session.commit()

    honest = _upload(client, headers, 1, _record(tasks.json[0], real_logs), real_logs)
    # the same logs, a record that claims the first checkpoint at 2 s: plausible, not true
    claimed = copy.deepcopy(_record(second.json[0], real_logs))
    end = claimed["score_events"][-1]
    claimed["score_events"].insert(
        -1, {**end, "kind": "checkpoint", "checkpoint": 1, "points": 1, "sim_time": 2.0}
    )
    claimed["score"] = 1
    forged = _upload(client, headers, 2, claimed, real_logs)

    jobs = list(db.session.scalars(select(Job).where(Job.kind == service.VERIFY)))
    assert sorted(job.target_id for job in jobs if job.target_id) == [honest, forged]
    for job in jobs:
        done = job_finished(job.id, REPLAY_WAIT_S)
        assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log}"
    shown = {
        run_id: client.get(f"/api/v1/runs/{run_id}", headers=officer).json
        for run_id in (honest, forged)
    }
    assert shown[honest]["verification"] == "verified", shown[honest]
    assert shown[forged]["verification"] == "held"
    reason = shown[forged]["verification_reason"]
    assert "the run claims 1 checkpoint(s), the replay reaches 0" in reason
    assert "the score log" not in reason  # the log itself is what the simulator wrote
    board = client.get("/api/v1/leaderboard", headers=officer).json
    (row,) = [s for s in board if s["team"] == "Team A"]
    assert (row["runs"], row["held"], row["unverified"]) == (1, 1, 0)
