"""Runs whose figures cannot be right are refused at the door (400 with the reason, nothing
stored), through the documented upload API with a team instance's own upload token."""

from __future__ import annotations

import copy
import hashlib
from collections.abc import Callable
from datetime import datetime, timedelta
from typing import Any

import pytest
from flask import Flask
from sqlalchemy import func, select

from cloudsim.extensions import db
from cloudsim.models import Artifact, PortalRefusal, Role, Run, utcnow
from cloudsim.portal.credentials import upload_token
from tests.conftest import make_user, token_for
from tests.portal.support import team_instance

LOGS = {
    "score.jsonl": b'{"event": "checkpoint", "checkpoint": 1}\n',
    "commands.jsonl": b'{"step": 0, "command": {"op": "behaviour", "name": "stand"}}\n',
    "meta.json": b'{"world": "vrc_task_2"}\n',
    "state.msgpack": b"\x00" * 64,
}


@pytest.fixture
def uploader(app: Flask) -> dict[str, Any]:
    """A team and its open task (90 s timeout), made through the documented API, and its
    instance's upload token."""
    client = app.test_client()
    officer = token_for(make_user(Role.OFFICER))
    team = client.post("/api/v1/teams", json={"name": "Team A"}, headers=officer).json
    now = utcnow()
    task = client.post(
        "/api/v1/tasks",
        json={
            "name": "Walking 1",
            "world": "vrc_task_2",
            "run_config": 1,
            "start": (now - timedelta(hours=1)).strftime("%Y-%m-%d %H:%M"),
            "stop": (now + timedelta(hours=1)).strftime("%Y-%m-%d %H:%M"),
            "time_zone": "UTC",
            "timeout_s": 90,
            "uplink_bits": 115_200,
            "downlink_bits": 59_000_000,
            "team_ids": [team["id"]],
        },
        headers=officer,
    )
    assert task.status_code == 201, task.json
    # the instance as a row: its upload token is what a deployed one is handed
    instance = team_instance(team["id"], "ti-a", "https://127.0.0.1:1/")
    headers = {"Authorization": f"Bearer {upload_token(instance)}"}
    db.session.commit()
    return {"task": task.json[0], "headers": headers, "officer": officer}


def honest_record(task: dict[str, Any]) -> dict[str, Any]:
    """A record whose figures add up: one checkpoint at 41 s of a 60 s run that lasted 75 s."""
    started = utcnow() - timedelta(minutes=5)
    return {
        "team": "Team A",
        "task_key": f"m{task['id']}",
        "task_name": task["name"],
        "world": "vrc_task_2",
        "run_config": 1,
        "state": "finished",
        "end_reason": "stopped",
        "score": 1,
        "falls": 1,
        "sim_seconds": 60.0,
        "uplink_bits_used": 100_000,
        "downlink_bits_used": 1_000_000,
        "uplink_bits": 115_200,
        "downlink_bits": 59_000_000,
        "timeout_s": 90,
        "seconds_left": 30.0,
        "started_at": started.isoformat(),
        "finished_at": (started + timedelta(seconds=75)).isoformat(),
        "score_events": [
            {
                "kind": "fall",
                "sim_time": 12.5,
                "wall_time": (started + timedelta(seconds=16)).isoformat(),
                "description": "fall 1",
            },
            {
                "kind": "checkpoint",
                "checkpoint": 1,
                "points": 1,
                "sim_time": 41.25,
                "wall_time": (started + timedelta(seconds=45)).isoformat(),
            },
            {
                "kind": "run_end",
                "sim_time": 60.0,
                "wall_time": (started + timedelta(seconds=64)).isoformat(),
                "description": "stopped",
            },
        ],
        "logs": [
            {
                "filename": name,
                "kind": name.split(".")[0],
                "size": len(content),
                "sha256": hashlib.sha256(content).hexdigest(),
            }
            for name, content in LOGS.items()
        ],
    }


def _events(record: dict[str, Any]) -> list[dict[str, Any]]:
    return record["score_events"]  # type: ignore[no-any-return]


def _checkpoint(record: dict[str, Any]) -> dict[str, Any]:
    return next(e for e in _events(record) if e["kind"] == "checkpoint")


def _score(record: dict[str, Any], score: int) -> None:
    record["score"] = score


def _extra_checkpoints(record: dict[str, Any], numbers: list[int], score: int) -> None:
    template = _checkpoint(record)
    for offset, number in enumerate(numbers, start=1):
        _events(record).insert(
            2 + offset, {**template, "checkpoint": number, "sim_time": 41.25 + offset}
        )
    record["score"] = score


def _set(path: str, value: Any) -> Callable[[dict[str, Any]], None]:
    def apply(record: dict[str, Any]) -> None:
        record[path] = value

    return apply


def _one_second_of_wall_clock(record: dict[str, Any]) -> None:
    started = datetime.fromisoformat(record["started_at"])
    record["finished_at"] = (started + timedelta(seconds=1)).isoformat()
    record.update(score_events=[], score=0, falls=0)


FORGERIES: dict[str, tuple[Callable[[dict[str, Any]], None], str]] = {
    # the issue's own forgery: score 9 on a world of 4 checkpoints
    "score above the world's checkpoints": (
        lambda r: _extra_checkpoints(r, [2, 3, 4, 5, 6, 7, 8, 9], 9),
        "score 9 on a world of 4 checkpoints",
    ),
    "events that do not add up to the score": (
        lambda r: _score(r, 2),
        "the score events add up to 1 point(s) over 1 checkpoint(s); the run claims a score of 2",
    ),
    "a checkpoint event worth two points": (
        lambda r: _checkpoint(r).update(points=2),
        "add up to 2 point(s)",
    ),
    "checkpoints out of order": (
        lambda r: (_checkpoint(r).update(checkpoint=2), _extra_checkpoints(r, [1], 2)),
        "score events out of order: checkpoint 2 is the 1. reached",
    ),
    "events out of time order": (
        lambda r: _events(r)[0].update(sim_time=50.0),
        "score events out of order: event 2 at 41.25 s comes after one at 50 s",
    ),
    "a checkpoint the world lacks": (
        lambda r: _checkpoint(r).update(checkpoint=7),
        "names checkpoint 7: the world has checkpoints 1 to 4",
    ),
    "simulated time beyond the timeout": (
        lambda r: r.update(sim_seconds=500.0, seconds_left=0.0),
        "500 simulated seconds against the task's timeout of 90 s",
    ),
    "falls beyond the limit": (_set("falls", 4), "4 falls: 3 falls end a run"),
    "more fall events than falls": (_set("falls", 0), "1 fall events, but the run claims 0"),
    "a simulated time the wall clock cannot hold": (
        _one_second_of_wall_clock,
        "60 simulated seconds in a run that lasted 1 seconds of wall-clock time",
    ),
    "a declared log missing": (
        lambda r: r.update(logs=[log for log in r["logs"] if log["filename"] != "commands.jsonl"]),
        "must declare the logs it is re-simulated from; missing: commands.jsonl",
    ),
    "complete without every checkpoint": (
        _set("end_reason", "complete"),
        "ended complete with 1 of the world's 4 checkpoints",
    ),
}


def test_an_honest_record_is_taken(app: Flask, uploader: dict[str, Any]) -> None:
    client = app.test_client()
    sent = client.put(
        "/api/v1/portal/ingest/runs/1",
        json=honest_record(uploader["task"]),
        headers=uploader["headers"],
    )
    assert sent.status_code == 200, sent.json
    assert db.session.scalar(select(func.count()).select_from(Run)) == 1


@pytest.mark.parametrize("forgery", FORGERIES, ids=list(FORGERIES))
def test_each_forged_field_is_refused_and_nothing_is_stored(
    app: Flask, uploader: dict[str, Any], forgery: str
) -> None:
    client = app.test_client()
    record = copy.deepcopy(honest_record(uploader["task"]))
    forge, reason = FORGERIES[forgery]
    forge(record)
    sent = client.put("/api/v1/portal/ingest/runs/1", json=record, headers=uploader["headers"])
    assert sent.status_code == 400, sent.json
    assert reason in sent.json["message"]
    db.session.rollback()
    assert db.session.scalar(select(func.count()).select_from(Run)) == 0
    refusals = client.get("/api/v1/portal/refusals", headers=uploader["officer"]).json
    assert [r["reason"] for r in refusals] == [sent.json["message"]]


def test_a_log_failing_its_checksum_is_refused_and_not_stored(
    app: Flask, uploader: dict[str, Any]
) -> None:
    client = app.test_client()
    base = "/api/v1/portal/ingest/runs/1"
    assert client.put(base, json=honest_record(uploader["task"]), headers=uploader["headers"])
    forged = LOGS["commands.jsonl"].replace(b"stand", b"walk!")  # same size, other bytes
    sent = client.put(
        f"{base}/logs/commands.jsonl?offset=0",
        data=forged,
        headers={**uploader["headers"], "Content-Type": "application/octet-stream"},
    )
    assert sent.status_code == 422, sent.json
    assert "commands.jsonl: checksum mismatch" in sent.json["message"]
    assert db.session.scalar(select(func.count()).select_from(Artifact)) == 0
    done = client.post(f"{base}/complete", headers=uploader["headers"])
    assert done.status_code == 409 and "commands.jsonl" in done.json["message"]
    assert db.session.scalar(select(func.count()).select_from(PortalRefusal)) == 1
