"""`cloudsim task`, `schedule`, `run`, `leaderboard`: JSON output and one-line errors."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest
from click.testing import Result
from flask import Flask

from cloudsim.competition.demo import DEMO_TASK, DemoJob, schedule_demo
from cloudsim.extensions import db
from cloudsim.models import Job, Task, Team
from tests.support.cli import migrated_cli
from tests.support.servers import RedisServer


@pytest.fixture
def run(tmp_path: Path, redis_server: RedisServer, encryption_key: str) -> Callable[..., Result]:
    return migrated_cli(tmp_path / "instance", redis_server.url(0), encryption_key)


def test_tasks_schedule_and_leaderboard_from_the_command_line(
    run: Callable[..., Result], tmp_path: Path
) -> None:
    assert run("team", "create", "Team Seven").exit_code == 0
    assert run("team", "create", "Team Eight").exit_code == 0
    added = run(
        "task", "add", "--name", "Walk 1", "--world", "vrc_task_2", "--config", "2",
        "--start", "2030-06-17 09:00", "--stop", "2030-06-17 12:00",
        "--time-zone", " America/Los_Angeles ", "--uplink-bits", "115200", "--json",
    )  # fmt: skip
    assert added.exit_code == 0, added.output
    tasks = json.loads(added.output)
    assert {t["team"] for t in tasks} == {"Team Seven", "Team Eight"}
    assert tasks[0]["window_start"] == "2030-06-17T16:00:00+00:00"
    assert tasks[0]["time_zone"] == "America/Los_Angeles"  # tidied as the pages and API do
    exported = run("schedule", "export")
    assert "time_zone: America/Los_Angeles" in exported.output
    assert "start: 2030-06-17 09:00" in exported.output and "teams:" not in exported.output
    season = tmp_path / "season.yaml"
    season.write_text(exported.output)
    assert "0 new task(s)" in run("schedule", "import", str(season)).output
    bad = run(
        "task", "add", "--name", "x", "--world", "vrc_task_1", "--start", "2030-01-02 09:00",
        "--stop", "2030-01-01 09:00",
    )  # fmt: skip
    assert bad.exit_code == 1 and "must end after it starts" in bad.output
    refused = run("run", "start", str(tasks[0]["id"]))
    assert refused.exit_code == 1 and "window" in refused.output
    board = json.loads(run("leaderboard", "--json").output)
    assert [s["rank"] for s in board] == [1, 1] and all(s["checkpoints"] == 0 for s in board)
    deleted = run("task", "delete", str(tasks[0]["id"]))
    assert deleted.exit_code == 0 and f"deleted task {tasks[0]['id']}" in deleted.output
    left = json.loads(run("task", "list", "--json").output)
    assert [t["id"] for t in left] == [tasks[1]["id"]]
    for command in (("task", "delete"), ("run", "start"), ("run", "stop"), ("run", "show")):
        huge = run(*command, "99999999999")  # past PostgreSQL's integer: click refuses it
        assert huge.exit_code == 2 and "Traceback" not in huge.output, command


def test_the_demo_schedules_its_task_once_and_starts_its_job(app: Flask, team_a: Team) -> None:
    first = schedule_demo(team_a.id, 1)
    second = schedule_demo(team_a.id, 1)
    [task] = db.session.query(Task).filter_by(name=DEMO_TASK).all()
    jobs = db.session.query(Job).filter_by(kind="competition.demo").all()
    assert {j.id for j in jobs} == {first.id, second.id}
    assert all(DemoJob.from_job(j) == DemoJob(task.id, 1) for j in jobs)
    assert all(
        (j.target_type, j.target_id, j.team_id) == ("task", task.id, team_a.id) for j in jobs
    )
