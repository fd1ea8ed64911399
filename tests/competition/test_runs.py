"""The server's rules for starting and stopping runs, for every caller, and the leaderboard."""

from __future__ import annotations

from dataclasses import replace
from datetime import timedelta
from pathlib import Path

import pytest
from flask import Flask

from cloudsim.competition import runs
from cloudsim.errors import Conflict, Forbidden
from cloudsim.extensions import db
from cloudsim.models import (
    Constellation,
    ConstellationState,
    Job,
    Run,
    RunState,
    Team,
    User,
    utcnow,
)
from tests.competition.support import finished_run, open_task
from tests.conftest import log_in, token_for


@pytest.fixture
def constellation(app: Flask, team_a: Team) -> Constellation:
    made = Constellation(
        name="a-vrc",
        kind="vrc",
        provider="local",
        team_id=team_a.id,
        state=ConstellationState.READY,
    )
    db.session.add(made)
    db.session.commit()
    return made


def test_a_team_user_starts_their_open_task_and_a_start_job_follows(
    app: Flask, people: dict[str, User | None], team_a: Team, constellation: Constellation
) -> None:
    task = open_task(team_a.id)
    run = runs.start_run(people["user_a"], task.id)
    assert run.state == RunState.STARTING and run.constellation_id == constellation.id
    job = db.session.query(Job).filter_by(target_type="run", target_id=run.id).one()
    assert job.kind == "run.start" and job.team_id == team_a.id
    with pytest.raises(Conflict, match="busy"):
        runs.start_run(people["user_a"], open_task(team_a.id).id)
    with pytest.raises(Conflict, match="run already"):
        runs.start_run(people["officer"], task.id)


def test_two_starts_of_a_task_at_once_on_two_constellations_start_one_run(
    app: Flask,
    people: dict[str, User | None],
    team_a: Team,
    constellation: Constellation,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    db.session.add(
        Constellation(
            name="a-vrc-2",
            kind="vrc",
            provider="local",
            team_id=team_a.id,
            state=ConstellationState.READY,
        )
    )
    task = open_task(team_a.id)
    first = runs.start_run(people["user_a"], task.id)
    db.session.commit()
    # the other start looked before this one was stored: the database refuses it
    looked, missed = runs.task_run, [None]
    monkeypatch.setattr(runs, "task_run", lambda *a: missed.pop() if missed else looked(*a))
    with pytest.raises(Conflict, match=f"run already \\(run {first.id}\\)"):
        runs.start_run(people["user_a"], task.id)
    assert db.session.query(Run).filter_by(task_id=task.id).count() == 1


def test_the_api_refuses_starts_outside_the_window_or_by_another_team(
    app: Flask, people: dict[str, User | None], team_a: Team, constellation: Constellation
) -> None:
    client = app.test_client()
    user_a, user_b = token_for(people["user_a"]), token_for(people["user_b"])  # type: ignore[arg-type]
    later = open_task(
        team_a.id,
        window_start=utcnow() + timedelta(hours=1),
        window_stop=utcnow() + timedelta(hours=2),
    )
    closed = open_task(
        team_a.id,
        window_start=utcnow() - timedelta(hours=2),
        window_stop=utcnow() - timedelta(hours=1),
    )
    task = open_task(team_a.id)
    not_yet = client.post(f"/api/v1/tasks/{later.id}/runs", json={}, headers=user_a)
    assert not_yet.status_code == 403 and "open for your team" in not_yet.json["message"]
    over = client.post(f"/api/v1/tasks/{closed.id}/runs", json={}, headers=user_a)
    assert over.status_code == 403 and "closed" in over.json["message"]
    other = client.post(f"/api/v1/tasks/{task.id}/runs", json={}, headers=user_b)
    assert other.status_code == 403 and other.json["message"] == not_yet.json["message"]
    constellation.state = ConstellationState.LAUNCHING
    db.session.commit()
    unready = client.post(f"/api/v1/tasks/{task.id}/runs", json={}, headers=user_a)
    assert unready.status_code == 409 and "launching" in unready.json["message"]
    assert db.session.query(Job).filter_by(kind="run.start").count() == 0


def test_a_team_starts_and_stops_a_run_through_the_api(
    app: Flask, people: dict[str, User | None], team_a: Team, constellation: Constellation
) -> None:
    open_task(team_a.id)
    client = app.test_client()
    user_a = token_for(people["user_a"])  # type: ignore[arg-type]
    [task] = client.get("/api/v1/tasks/open", headers=user_a).json
    started = client.post(f"/api/v1/tasks/{task['id']}/runs", json={}, headers=user_a)
    assert started.status_code == 202 and started.json["state"] == "starting", started.json
    run_id = started.json["id"]
    assert started.json["constellation_id"] == constellation.id
    db.session.get(Run, run_id).state = RunState.RUNNING  # type: ignore[union-attr]
    db.session.commit()
    stopped = client.post(f"/api/v1/runs/{run_id}/stop", headers=user_a)
    assert stopped.status_code == 202 and stopped.json["state"] == "stopping", stopped.json
    shown = client.get(f"/api/v1/runs/{run_id}", headers=user_a).json
    assert shown["stop_reason"] == "stopped" and shown["state"] == "stopping"


def test_a_team_without_a_constellation_is_told_so(
    app: Flask, people: dict[str, User | None], team_b: Team
) -> None:
    with pytest.raises(Conflict, match="no constellation"):
        runs.start_run(people["user_b"], open_task(team_b.id).id)


def test_stopping_marks_the_reason_once_and_only_the_team_may(
    app: Flask, people: dict[str, User | None], team_a: Team, constellation: Constellation
) -> None:
    run = runs.start_run(people["user_a"], open_task(team_a.id).id)
    run.state = RunState.RUNNING
    db.session.commit()
    with pytest.raises(Exception, match="not found"):
        runs.stop_run(people["user_b"], run.id)
    runs.stop_run(people["user_a"], run.id)
    runs.stop_run(people["user_a"], run.id)  # a second click changes nothing
    assert run.state == RunState.STOPPING and run.stop_reason == "stopped"
    assert db.session.query(Job).filter_by(kind="run.stop", target_id=run.id).count() == 1


def test_the_leaderboard_setting_limits_what_team_users_see(
    app: Flask,
    people: dict[str, User | None],
    team_a: Team,
    team_b: Team,
    constellation: Constellation,
    tmp_path: Path,
) -> None:
    finished_run(open_task(team_a.id), constellation.id, tmp_path, score=3)
    finished_run(open_task(team_b.id), None, tmp_path, score=1)
    board = runs.leaderboard(people["user_a"])
    assert [(s.team, s.checkpoints, s.rank) for s in board] == [("Team A", 3, 1), ("Team B", 1, 2)]
    config = app.config["CLOUDSIM"]
    for policy, expected in (("own", ["Team A"]), ("none", None)):
        app.config["CLOUDSIM"] = replace(config, leaderboard_for_users=policy)
        try:
            if expected is None:
                with pytest.raises(Forbidden):
                    runs.leaderboard(people["user_a"])
                assert len(runs.leaderboard(people["officer"])) == 2
            else:
                assert [s.team for s in runs.leaderboard(people["user_a"])] == expected
        finally:
            app.config["CLOUDSIM"] = config


def test_the_tasks_page_offers_the_open_task_and_hides_later_ones(
    app: Flask, people: dict[str, User | None], team_a: Team, constellation: Constellation
) -> None:
    open_task(team_a.id, name="Open one")
    open_task(
        team_a.id,
        name="Secret later one",
        window_start=utcnow() + timedelta(hours=1),
        window_stop=utcnow() + timedelta(hours=2),
    )
    client = app.test_client()
    log_in(client, people["user_a"])  # type: ignore[arg-type]
    page = client.get("/tasks").get_data(as_text=True)
    assert "Open one" in page and "Start run" in page and "Secret later one" not in page
    dashboard = client.get("/").get_data(as_text=True)
    assert "Open one" in dashboard and "Secret later one" not in dashboard


def test_the_beat_restarts_a_failed_stop_job_a_few_times_then_leaves_it(
    app: Flask, people: dict[str, User | None], team_a: Team, constellation: Constellation
) -> None:
    from cloudsim.competition.supervision import MAX_STOP_ATTEMPTS, supervise_runs
    from cloudsim.models import JobState

    run = runs.start_run(people["user_a"], open_task(team_a.id).id)
    run.state = RunState.RUNNING
    db.session.commit()
    runs.stop_run(people["user_a"], run.id)
    db.session.commit()
    for attempt in range(1, MAX_STOP_ATTEMPTS + 1):
        stops = db.session.query(Job).filter_by(kind="run.stop", target_id=run.id).all()
        assert len(stops) == attempt
        assert supervise_runs() == 0  # the latest stop job has not failed
        for job in stops:
            job.state = JobState.FAILED
        db.session.commit()
        assert supervise_runs() == (1 if attempt < MAX_STOP_ATTEMPTS else 0)


def test_the_beat_stops_runs_at_the_end_of_the_window_and_past_the_timeout(
    app: Flask, people: dict[str, User | None], team_a: Team, constellation: Constellation
) -> None:
    from cloudsim.competition.supervision import supervise_runs

    task = open_task(team_a.id, timeout_s=60)
    run = runs.start_run(people["user_a"], task.id)
    run.state, run.running_at = RunState.RUNNING, utcnow() - timedelta(hours=1)
    db.session.commit()
    assert supervise_runs() == 1  # an hour past a 60 s timeout (and its grace)
    assert (run.state, run.stop_reason) == (RunState.STOPPING, "timeout")

    run.state, run.active_constellation_id = RunState.ERROR, None
    db.session.commit()
    closing = runs.start_run(people["user_a"], open_task(team_a.id).id)
    closing.state = RunState.RUNNING
    closing.task.window_stop = utcnow() - timedelta(seconds=1)
    db.session.commit()
    assert supervise_runs() == 1
    assert (closing.state, closing.stop_reason) == (RunState.STOPPING, "window")


def test_the_officer_dashboard_shows_live_runs(
    app: Flask, people: dict[str, User | None], team_a: Team, constellation: Constellation
) -> None:
    run = runs.start_run(people["user_a"], open_task(team_a.id, name="Live one").id)
    client = app.test_client()
    log_in(client, people["officer"])  # type: ignore[arg-type]
    page = client.get("/").get_data(as_text=True)
    assert "1 task(s) open now" in page and f'/runs/{run.id}"' in page and "starting" in page


def test_the_run_page_shows_plots_bits_left_and_logs_to_download(
    app: Flask,
    people: dict[str, User | None],
    team_a: Team,
    constellation: Constellation,
    tmp_path: Path,
) -> None:
    from cloudsim.competition.artifacts import LogStore, file_sha256
    from cloudsim.models import Artifact
    from tests.competition.test_scoring import bandwidth_log

    run = finished_run(open_task(team_a.id), constellation.id, tmp_path, score=1)
    run.uplink_bits_used = 32_000
    path = tmp_path / "bandwidth.jsonl"
    path.write_text("\n".join(bandwidth_log()))
    store = LogStore(app.config["CLOUDSIM"])
    store.put(path, store.object_name(run.id, path.name))
    db.session.add(
        Artifact(
            run_id=run.id,
            kind="bandwidth",
            filename=path.name,
            location=store.object_name(run.id, path.name),
            size=path.stat().st_size,
            sha256=file_sha256(path),
        )
    )
    db.session.commit()
    client = app.test_client()
    log_in(client, people["user_a"])  # type: ignore[arg-type]
    page = client.get(f"/runs/{run.id}").get_data(as_text=True)
    assert page.count("<svg") == 5 and "Score timeline" in page and "cap 80k" in page
    assert "968,000" in page  # 1,000,000 uplink bits minus 32,000 used
    status = client.get(f"/runs/{run.id}/status").json
    assert status["state"] == "finished" and status["bits_left"]["uplink"] == 968_000
    artifact = next(a for a in run.artifacts if a.filename == "bandwidth.jsonl")
    download = client.get(f"/runs/{run.id}/logs/{artifact.id}")
    assert download.data == path.read_bytes()
    assert download.headers["X-Checksum-SHA256"] == artifact.sha256
