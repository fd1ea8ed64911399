"""A season's runs uploaded to the portal the way team instances send them, timed (bench/portal).

Each team gets a team instance (a row with its upload token) and 15 tasks of the past; one
uploader per instance, all at once, sends each run through the documented ingest API: the
record with its score events, each log in one piece, then the acknowledgement.
"""

from __future__ import annotations

import hashlib
import statistics
import threading
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from typing import Any

import requests
from flask import Flask
from sqlalchemy import select

from cloudsim.extensions import db
from cloudsim.models import Constellation, Task, Team, TeamInstance, utcnow
from cloudsim.models.team_instances import InstanceState
from cloudsim.portal.credentials import upload_token
from tests.support.season import bandwidth_log, score_log

INGEST = "/api/v1/portal/ingest/runs"
CHECKPOINTS = 8


@dataclass(frozen=True)
class Log:
    """A log every uploaded run carries (the same bytes each time: sizes are what matter)."""

    filename: str
    kind: str
    body: bytes
    sha256: str = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "sha256", hashlib.sha256(self.body).hexdigest())


@dataclass(frozen=True)
class Uploader:
    """One team instance: its token, its team, the tasks (id, start, name) of its season's
    runs, and its runs with a state log (its id for the run, the task)."""

    token: str
    team: str
    tasks: list[tuple[int, datetime, str]]
    extra: list[tuple[int, tuple[int, datetime, str]]] = field(default_factory=list)


def prepare(app: Flask, runs_per_team: int, large: int = 0) -> list[Uploader]:
    """Give each team an instance with an upload token and tasks of the past, the first
    `large` teams one more task, for a run with a state log (committed)."""
    with app.app_context():
        uploaders: list[Uploader] = []
        now = utcnow()
        for team in db.session.scalars(select(Team).order_by(Team.id)):
            constellation = Constellation(
                name=f"portal-{team.id}", kind="cloudsim", provider="local", team_id=team.id
            )
            db.session.add(constellation)
            db.session.flush()
            instance = TeamInstance(
                name=f"team-{team.id}",
                team_id=team.id,
                constellation_id=constellation.id,
                # stand-ins (nothing answers at their addresses): not ready, so no sync job
                # is started for them; the upload token only needs an instance not terminated
                state=InstanceState.UNREACHABLE,
                url=f"https://192.0.2.{team.id % 250}",
            )
            db.session.add(instance)
            db.session.flush()
            tasks = []
            for n in range(runs_per_team + (len(uploaders) < large)):
                start = now - timedelta(days=2, hours=n)
                task = Task(
                    team_id=team.id,
                    name=f"Uploaded {n + 1}",
                    world="vrc_task_2",
                    run_config=1,
                    window_start=start,
                    window_stop=start + timedelta(hours=1),
                    uplink_bits=8_000_000,
                    downlink_bits=64_000_000,
                )
                db.session.add(task)
                db.session.flush()
                tasks.append((task.id, start, task.name))
            extra = [(runs_per_team + 1, task) for task in tasks[runs_per_team:]]
            uploaders.append(
                Uploader(upload_token(instance), team.name, tasks[:runs_per_team], extra)
            )
        db.session.commit()
        return uploaders


def record(uploader: Uploader, task_id: int, start: datetime, name: str) -> dict[str, Any]:
    """Return the record an instance sends for its run of a task (no logs declared yet)."""

    def at(seconds: float) -> str:
        return (start + timedelta(seconds=seconds)).astimezone(UTC).isoformat()

    return {
        "team": uploader.team,
        "task_key": f"m{task_id}",
        "task_name": name,
        "world": "vrc_task_2",
        "run_config": 1,
        "state": "finished",
        "end_reason": "time_limit",
        "score": CHECKPOINTS,
        "falls": 0,
        "sim_seconds": 10.0 * CHECKPOINTS,
        "uplink_bits_used": 1_000_000 + task_id,
        "downlink_bits_used": 8_000_000,
        "uplink_bits": 8_000_000,
        "downlink_bits": 64_000_000,
        "timeout_s": 1800,
        "seconds_left": 1800 - 10.0 * CHECKPOINTS,
        "started_at": at(0),
        "running_at": at(5),
        "finished_at": at(1800),
        "score_events": [
            {
                "kind": "checkpoint",
                "checkpoint": n,
                "points": 1,
                "sim_time": 10.0 * n,
                "wall_time": at(10 * n),
                "description": f"checkpoint {n}",
            }
            for n in range(1, CHECKPOINTS + 1)
        ],
        "logs": [],
    }


def small_logs(log_seconds: int = 1800) -> list[Log]:
    """Return the logs every run carries: its score log and its bandwidth log, and (tiny
    here) the logs a finished run must declare to be re-simulated."""
    return [
        Log("score.jsonl", "score", score_log(CHECKPOINTS).encode()),
        Log("bandwidth.jsonl", "bandwidth", bandwidth_log(log_seconds).encode()),
        Log("commands.jsonl", "commands", b""),
        Log("meta.json", "meta", b"{}\n"),
        Log("state.msgpack", "state", b""),
    ]


def upload(base: str, uploaders: list[Uploader], log_seconds: int = 1800) -> dict[str, Any]:
    """Send every season's run of every uploader at once; return the counts and timings."""
    logs = small_logs(log_seconds)
    declared: list[dict[str, Any]] = [
        {"filename": x.filename, "kind": x.kind, "size": len(x.body), "sha256": x.sha256}
        for x in logs
    ]
    per_run: list[float] = []
    errors: list[str] = []
    lock = threading.Lock()

    def send(me: Uploader) -> None:
        http = requests.Session()
        http.headers["Authorization"] = f"Bearer {me.token}"
        for remote_id, (task_id, start, name) in enumerate(me.tasks, 1):
            began = time.perf_counter()
            url = f"{base}{INGEST}/{remote_id}"
            answers = [http.put(url, json={**record(me, task_id, start, name), "logs": declared})]
            for log in logs:
                answers.append(
                    http.put(
                        f"{url}/logs/{log.filename}",
                        params={"offset": 0},
                        data=log.body,
                        headers={"Content-Type": "application/octet-stream"},
                    )
                )
            answers.append(http.post(f"{url}/complete"))
            with lock:
                per_run.append(time.perf_counter() - began)
                errors.extend(f"{a.status_code} {a.text[:120]}" for a in answers if not a.ok)

    started = time.perf_counter()
    threads = [threading.Thread(target=send, args=(u,)) for u in uploaders]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    wall = time.perf_counter() - started
    if errors:
        raise SystemExit(f"{len(errors)} refused uploads, e.g. {errors[:3]}")
    ordered = sorted(per_run)
    return {
        "runs": len(per_run),
        "instances": len(uploaders),
        "seconds": wall,
        "bytes": len(per_run) * sum(len(x.body) for x in logs),
        "p50": statistics.median(ordered),
        "p95": ordered[int(0.95 * (len(ordered) - 1))],
    }
