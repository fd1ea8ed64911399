"""A competition season's rows, added straight to the database (bench/web.py and page tests).

Every kind of row a page or API list reads grows with it: teams and their members, ready
constellations and machines, jobs, audit events, tokens and SSH keys, tasks (one per run and
one open now), and finished runs with score events and stored score and bandwidth logs.
"""

from __future__ import annotations

import functools
import itertools
import json
import tempfile
import uuid
from collections.abc import Iterable, Sequence
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

from flask import Flask, url_for
from sqlalchemy import select

from cloudsim.auth.ssh_keys import ParsedKey, parse_public_key
from cloudsim.competition.artifacts import LogStore, file_sha256
from cloudsim.extensions import db
from cloudsim.launched_constellations.keys import generate_keypair
from cloudsim.models import (
    ApiToken,
    Artifact,
    AuditEvent,
    Constellation,
    ConstellationState,
    Job,
    JobState,
    Machine,
    MachineState,
    Phase,
    Role,
    Run,
    RunState,
    ScoreEvent,
    SshKey,
    Task,
    Team,
    TeamInstance,
    User,
    utcnow,
)

ROLES = ("router", "sim", "fc1", "fc2")
_serial = itertools.count(1)


def new_teams(count: int) -> list[Team]:
    """Add `count` teams with fresh names (the caller commits)."""
    teams = [Team(name=f"Season team {next(_serial):04d}") for _ in range(count)]
    db.session.add_all(teams)
    db.session.flush()
    return teams


def add_season(
    store: LogStore,
    teams: Sequence[Team],
    password_hash: str,
    *,
    users: int = 1,
    runs: int = 1,
    jobs: int = 1,
    events: int = 4,
    log_seconds: int = 60,
) -> None:
    """Add to each team members, one ready four-machine constellation, jobs and finished runs.

    Each run has its own task, `events` score events and a stored score log and bandwidth log
    of `log_seconds` seconds; each team also gets one task open now. The caller commits.
    """
    now = utcnow()
    with tempfile.TemporaryDirectory(prefix="cloudsim-season-") as folder:
        bandwidth = Path(folder) / "bandwidth.jsonl"
        bandwidth.write_text(bandwidth_log(log_seconds))
        score = Path(folder) / "score.jsonl"
        score.write_text(score_log(events))
        for team in teams:
            _add_people(team, users, password_hash)
            _add_constellation(team)
            db.session.add_all(_jobs(team, jobs))
            db.session.add(_task(team, now - timedelta(minutes=1), now + timedelta(days=1)))
            for n in range(runs):
                _add_run(store, team, now - timedelta(days=1, hours=n), events, score, bandwidth)
    db.session.flush()


def _add_people(team: Team, count: int, password_hash: str) -> None:
    for _ in range(count):
        user = User(
            email=f"member{next(_serial)}@example.org",
            role=Role.USER,
            team_id=team.id,
            password_hash=password_hash,
        )
        add_credentials(user, 1)
        db.session.add(user)
        db.session.add(AuditEvent(action="user.create", target_type="user", team_id=team.id))


def add_credentials(user: User, count: int) -> None:
    """Give the user `count` more API tokens and SSH keys (the caller commits)."""
    # Rows, not the services: a key added through them would push it to the team's ready
    # constellations (a job per key), which a seeded season has no use for.
    for n in range(len(user.ssh_keys), len(user.ssh_keys) + count):
        user.tokens.append(
            ApiToken(name="season", prefix="cst_season", token_hash=uuid.uuid4().hex * 2)
        )
        key = _public_key(n)
        user.ssh_keys.append(
            SshKey(
                name=f"season {n}",
                key_type=key.key_type,
                bits=key.bits,
                public_key=key.public_key,
                fingerprint=key.fingerprint,
            )
        )


@functools.cache
def _public_key(number: int) -> ParsedKey:
    """Return the number-th of a few keys (a user's keys must differ; users may share)."""
    return parse_public_key(generate_keypair(f"season {number}").public)


def _add_constellation(team: Team) -> None:
    constellation = Constellation(
        name=f"vrc-{next(_serial)}",
        kind="vrc",
        provider="local",
        team_id=team.id,
        state=ConstellationState.READY,
    )
    for n, role in enumerate(ROLES):
        constellation.machines.append(
            Machine(
                name=role,
                role=role,
                state=MachineState.READY,
                private_ip=f"10.{team.id % 250}.0.{50 + n}",
            )
        )
    db.session.add(constellation)


def _jobs(team: Team, count: int) -> list[Job]:
    return [
        Job(
            id=str(uuid.uuid4()),
            kind="diagnostics",
            state=JobState.SUCCEEDED,
            team_id=team.id,
            progress=100,
            log="ok\n" * 20,
        )
        for _ in range(count)
    ]


def _task(team: Team, start: datetime, stop: datetime) -> Task:
    task = Task(
        team_id=team.id,
        name=f"Task {next(_serial)}",
        world="vrc_task_2",
        run_config=1,
        window_start=start,
        window_stop=stop,
        uplink_bits=8_000_000,
        downlink_bits=64_000_000,
    )
    db.session.add(task)
    return task


def _add_run(
    store: LogStore, team: Team, start: datetime, events: int, score: Path, bandwidth: Path
) -> None:
    task = _task(team, start, start + timedelta(hours=1))
    db.session.flush()
    run = Run(
        task_id=task.id,
        team_id=team.id,
        state=RunState.FINISHED,
        score=events,
        sim_seconds=float(10 * events),
        uplink_bits_used=1_000_000,
        downlink_bits_used=8_000_000,
        end_reason="time_limit",
        started_at=start,
        finished_at=start + timedelta(minutes=30),
    )
    run.score_events = [
        ScoreEvent(
            checkpoint=n + 1,
            points=1,
            sim_time=float(10 * (n + 1)),
            wall_time=start + timedelta(seconds=10 * (n + 1)),
            description=f"checkpoint {n + 1}",
        )
        for n in range(events)
    ]
    db.session.add(run)
    db.session.flush()
    for path in (score, bandwidth):
        name = store.object_name(run.id, path.name)
        store.put(path, name)
        run.artifacts.append(
            Artifact(
                kind=path.stem,
                filename=path.name,
                location=name,
                size=path.stat().st_size,
                sha256=file_sha256(path),
            )
        )
    db.session.add(
        AuditEvent(action="run.start", target_type="run", target_id=str(run.id), team_id=team.id)
    )


def score_log(events: int) -> str:
    """Return a simulator score log with `events` checkpoints, ten simulated seconds apart."""
    lines = [{"event": "run_start", "score": 0, "sim_time": 0.0, "wall_time": 1.8e9}]
    lines += [
        {
            "event": "checkpoint",
            "checkpoint": n,
            "name": f"checkpoint {n}",
            "points": 1,
            "score": n,
            "sim_time": 10.0 * n,
            "wall_time": 1.8e9 + 10 * n,
        }
        for n in range(1, events + 1)
    ]
    return "".join(json.dumps(line) + "\n" for line in lines)


def bandwidth_log(
    seconds: int, uplink_bytes: int = 400, caps: tuple[int, int] = (8_000_000, 64_000_000)
) -> str:
    """Return a router bandwidth log of `seconds` seconds of traffic both ways (about
    `uplink_bytes` a second up), armed with (uplink, downlink) `caps`."""
    lines: list[dict[str, object]] = [
        {
            "time": "2026-06-17T16:00:00.000+00:00",
            "event": "armed",
            "caps_bits": {"uplink": caps[0], "downlink": caps[1]},
        }
    ]
    total = {"uplink": 0, "downlink": 0}
    for second in range(1, seconds + 1):
        sizes = (("uplink", uplink_bytes + second % 7), ("downlink", 4000 + second % 11))
        for direction, size in sizes:
            total[direction] += size
            lines.append(
                {
                    "second": second,
                    "direction": direction,
                    "bytes": size,
                    "cumulative_bytes": total[direction],
                    "cap_remaining_bits": None,
                }
            )
    return "".join(json.dumps(line) + "\n" for line in lines)


def team_urls(app: Flask, team_id: int, endpoints: Iterable[str]) -> dict[str, str]:
    """Return endpoint -> URL of GET routes, their ids pointing at the team's newest rows."""
    run = db.session.scalar(
        select(Run).where(Run.team_id == team_id).order_by(Run.id.desc()).limit(1)
    )
    assert run is not None, "the team has no run: seed a season first"
    ids: dict[str, Any] = {
        "team_id": team_id,
        "user_id": db.session.scalar(select(User.id).where(User.team_id == team_id).limit(1)),
        "job_id": db.session.scalar(select(Job.id).where(Job.team_id == team_id).limit(1)),
        "ref": db.session.scalar(
            select(Constellation.id).where(Constellation.team_id == team_id).limit(1)
        ),
        "task_id": run.task_id,
        "run_id": run.id,
        "artifact_id": run.artifacts[0].id,
        "name": "vrc_task_1",  # a world
    }
    phase = db.session.scalar(select(Phase.id).order_by(Phase.id.desc()).limit(1))
    if phase is not None:  # a season with phases
        ids["phase_id"] = phase
    instance = db.session.scalar(select(TeamInstance.id).order_by(TeamInstance.id.desc()))
    if instance is not None:  # a season with team instances (their pages need one)
        ids["instance_id"] = instance
    wanted = set(endpoints)
    found = {}
    with app.test_request_context():
        for rule in app.url_map.iter_rules():
            if rule.endpoint in wanted and "GET" in (rule.methods or ()):
                if not rule.arguments <= ids.keys():
                    continue  # e.g. instances' pages in a season without any, upload routes
                values = {k: v for k, v in ids.items() if k in rule.arguments}
                found[rule.endpoint] = url_for(rule.endpoint, **values)
    return found
