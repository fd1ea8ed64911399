"""Scheduling: time zones, windows, who sees what, the season's YAML both ways, bad input."""

from __future__ import annotations

import io
from datetime import UTC, datetime, timedelta

import pytest
import sqlalchemy as sa
from flask import Flask

from cloudsim.competition import schedule, season
from cloudsim.errors import Forbidden, InvalidInput, NotFound
from cloudsim.extensions import db
from cloudsim.models import Task, Team, User, utcnow
from tests.conftest import csrf_token, log_in, token_for

SEASON = """\
time_zone: America/Los_Angeles
tasks:
  - name: Driving, run 1
    world: vrc_task_1
    config: 1
    start: 2026-06-17 09:00
    stop: 2026-06-17 12:00
    timeout_s: 1800
    latency_ms: 250
    uplink_bits: 115200
    downlink_bits: 59000000
    order: 1
  - name: Walking, run 2
    world: vrc_task_2
    config: 2
    start: 2026-06-18 09:30
    stop: 2026-06-18 11:00
    order: 2
    teams: [Team B]
  - name: Manipulation, run 3
    world: vrc_task_3
    config: 3
    start: 2026-06-19 08:00
    stop: 2026-06-19 10:00
    time_zone: Europe/Berlin
"""


def spec(**fields: object) -> schedule.TaskSpec:
    now = utcnow()
    values: dict[str, object] = dict(
        name="Walk",
        world="vrc_task_2",
        run_config=1,
        window_start=now - timedelta(minutes=5),
        window_stop=now + timedelta(minutes=5),
    )
    values.update(fields)
    return schedule.TaskSpec(**values)  # type: ignore[arg-type]


def test_a_window_entered_in_a_zone_is_stored_in_utc(app: Flask) -> None:
    start = schedule.to_utc("2026-06-17 09:00", "America/Los_Angeles")
    assert start == datetime(2026, 6, 17, 16, 0, tzinfo=UTC)  # PDT is UTC-7 in June
    assert schedule.to_utc("2026-01-17T09:00", "Europe/Berlin").hour == 8  # CET is UTC+1
    with pytest.raises(InvalidInput, match="unknown time zone"):
        schedule.to_utc("2026-06-17 09:00", "Mars/Olympus")
    with pytest.raises(InvalidInput, match="not a time"):
        schedule.to_utc("tomorrow morning", "UTC")


def test_scheduling_for_every_team_makes_one_task_per_team(
    app: Flask, people: dict[str, User | None], team_a: Team, team_b: Team
) -> None:
    tasks = schedule.schedule(people["officer"], spec(), None)
    assert sorted(t.team_id for t in tasks) == sorted([team_a.id, team_b.id])
    only_b = schedule.schedule(people["officer"], spec(name="B only"), [team_b.id])
    assert [t.team_id for t in only_b] == [team_b.id]
    with pytest.raises(Forbidden):
        schedule.schedule(people["user_a"], spec(), None)


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"world": "vrc_task_9"}, "unknown world"),
        ({"run_config": 6}, "no run configuration 6"),
        ({"window_stop": utcnow() - timedelta(hours=1)}, "must end after"),
        ({"timeout_s": 0}, "timeout"),
        ({"latency_ms": 5000}, "latency"),
        ({"uplink_bits": -1}, "uplink cap"),
        ({"name": "  "}, "task name"),
        ({"time_zone": "Nowhere/Town"}, "time zone"),
    ],
)
def test_bad_tasks_are_refused_with_the_reason(
    app: Flask, people: dict[str, User | None], fields: dict[str, object], message: str
) -> None:
    with pytest.raises(InvalidInput, match=message):
        schedule.schedule(people["officer"], spec(**fields), None)


def test_team_users_see_their_tasks_only_once_the_window_opened(
    app: Flask, people: dict[str, User | None], team_a: Team
) -> None:
    officer, user_a, user_b = people["officer"], people["user_a"], people["user_b"]
    [open_now] = schedule.schedule(officer, spec(name="Open"), [team_a.id])
    future = spec(
        name="Later",
        window_start=utcnow() + timedelta(hours=1),
        window_stop=utcnow() + timedelta(hours=2),
    )
    [later] = schedule.schedule(officer, future, [team_a.id])
    [past] = schedule.schedule(
        officer,
        spec(name="Past", window_start=utcnow() - timedelta(hours=2), window_stop=utcnow()),
        [team_a.id],
    )
    seen = set(db.session.scalars(schedule.visible_tasks(user_a)))
    assert seen == {open_now, past}
    assert schedule.open_tasks(user_a) == [open_now]
    assert schedule.open_tasks(user_b) == []
    with pytest.raises(NotFound):
        schedule.get_task(user_a, later.id)
    with pytest.raises(NotFound):
        schedule.get_task(user_b, open_now.id)
    assert schedule.get_task(officer, later.id) is later


def test_the_api_hides_unopened_tasks_and_answers_400_to_bad_input(
    app: Flask, people: dict[str, User | None], team_a: Team
) -> None:
    client = app.test_client()
    officer = token_for(people["officer"])  # type: ignore[arg-type]
    body = {
        "name": "Later",
        "world": "vrc_task_1",
        "start": "2030-01-01 09:00",
        "stop": "2030-01-01 12:00",
        "time_zone": "Asia/Tokyo",
        "team_ids": [team_a.id],
    }
    created = client.post("/api/v1/tasks", json=body, headers=officer)
    assert created.status_code == 201, created.json
    assert created.json[0]["window_start"].startswith("2030-01-01T00:00:00")  # 09:00 JST
    user = token_for(people["user_a"])  # type: ignore[arg-type]
    assert client.get("/api/v1/tasks", headers=user).json == []
    task_id = created.json[0]["id"]
    assert client.get(f"/api/v1/tasks/{task_id}", headers=user).status_code == 404
    for bad, message in (
        ({**body, "world": "moon"}, "unknown world"),
        ({**body, "stop": "2029-12-31 09:00"}, "must end after"),
        ({**body, "start": "soon"}, "not a time"),
        ({**body, "time_zone": "Atlantis/Capital"}, "unknown time zone"),
        ({**body, "team_ids": [9999]}, "team 9999 not found"),
    ):
        answer = client.post("/api/v1/tasks", json=bad, headers=officer)
        assert answer.status_code in (400, 404) and message in answer.json["message"], answer.json
    assert client.post("/api/v1/tasks", json={"name": "x"}, headers=officer).status_code == 400
    bad_yaml = client.post("/api/v1/schedule", json={"yaml": "tasks: [{name: x"}, headers=officer)
    assert bad_yaml.status_code == 400 and "not valid YAML" in bad_yaml.json["message"]


def test_a_season_imports_exports_and_imports_again_unchanged(
    app: Flask, people: dict[str, User | None], team_a: Team, team_b: Team
) -> None:
    officer = people["officer"]
    created = season.import_season(officer, SEASON)
    assert len(created) == 2 + 1 + 2  # every team, team B only, every team
    walking = next(t for t in created if t.name == "Walking, run 2")
    assert walking.team_id == team_b.id
    assert walking.window_start == datetime(2026, 6, 18, 16, 30, tzinfo=UTC)
    manipulation = next(t for t in created if t.name == "Manipulation, run 3")
    assert manipulation.window_start == datetime(2026, 6, 19, 6, 0, tzinfo=UTC)  # CEST
    exported = season.export_season(officer)
    assert season.import_season(officer, exported) == []  # the same tasks: nothing new
    assert season.export_season(officer) == exported
    rows = {(t.team_id, t.name, t.window_start, t.uplink_bits) for t in db.session.query(Task)}
    db.session.query(Task).delete()
    db.session.commit()
    season.import_season(officer, exported)
    again = {(t.team_id, t.name, t.window_start, t.uplink_bits) for t in db.session.query(Task)}
    assert again == rows


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("- just a list", "mapping with a 'tasks' list"),
        ("tasks: [{name: x, world: vrc_task_1, start: 2026-01-01 09:00}]", "missing stop"),
        ("tasks: [{name: x, world: vrc_task_1, start: 1, stop: 2, colour: red}]", "unknown keys"),
        ("time_zone: Moon/Base\ntasks: []", "unknown time zone"),
        (
            "tasks: [{name: x, world: vrc_task_1, start: 2026-01-01 09:00, "
            "stop: 2026-01-01 10:00, teams: [Team Z]}]",
            "no team named 'Team Z'",
        ),
    ],
)
def test_bad_season_documents_say_what_is_wrong(
    app: Flask, people: dict[str, User | None], text: str, message: str
) -> None:
    with pytest.raises((InvalidInput, NotFound), match=message):
        season.import_season(people["officer"], text)
    assert db.session.query(Task).count() == 0


def test_an_officer_imports_a_season_and_deletes_a_task_through_the_pages(
    app: Flask, people: dict[str, User | None], team_a: Team, team_b: Team
) -> None:
    client = app.test_client()
    log_in(client, people["officer"])  # type: ignore[arg-type]
    page = client.get("/tasks").get_data(as_text=True)
    upload = (io.BytesIO(SEASON.encode()), "season.yaml")
    imported = client.post(
        "/tasks/import",
        data={"csrf_token": csrf_token(page), "schedule_file": upload},
        content_type="multipart/form-data",
        follow_redirects=True,
    )
    assert "Imported the schedule: 5 new task(s)." in imported.get_data(as_text=True)
    walking = db.session.query(Task).filter_by(name="Walking, run 2").one().id
    page = client.get("/tasks").get_data(as_text=True)
    assert f'action="/tasks/{walking}/delete"' in page
    deleted = client.post(
        f"/tasks/{walking}/delete", data={"csrf_token": csrf_token(page)}, follow_redirects=True
    )
    assert "Task deleted." in deleted.get_data(as_text=True)
    db.session.expire_all()
    assert db.session.get(Task, walking) is None and db.session.query(Task).count() == 4


def test_an_officer_imports_a_season_and_deletes_a_task_through_the_api(
    app: Flask, people: dict[str, User | None], team_a: Team, team_b: Team
) -> None:
    client = app.test_client()
    officer = token_for(people["officer"])  # type: ignore[arg-type]
    created = client.post("/api/v1/schedule", json={"yaml": SEASON}, headers=officer)
    assert created.status_code == 201 and len(created.json) == 5, created.json
    exported = client.get("/api/v1/schedule", headers=officer).json["yaml"]
    assert "Walking, run 2" in exported
    task_id = created.json[0]["id"]
    assert client.delete(f"/api/v1/tasks/{task_id}", headers=officer).status_code == 204
    assert client.get(f"/api/v1/tasks/{task_id}", headers=officer).status_code == 404
    assert len(client.get("/api/v1/tasks", headers=officer).json) == 4


def test_the_exported_season_shows_every_change_at_once(
    app: Flask, people: dict[str, User | None], team_a: Team, team_b: Team
) -> None:
    # The document is kept per process for the rows it was drawn from: nothing may go stale.
    client = app.test_client()
    officer = token_for(people["officer"])  # type: ignore[arg-type]
    assert (
        client.post("/api/v1/schedule", json={"yaml": SEASON}, headers=officer).status_code == 201
    )

    def exported() -> str:
        return str(client.get("/api/v1/schedule", headers=officer).json["yaml"])

    first = exported()
    assert exported() == first and "Team A" not in first  # every team runs runs 1 and 3
    driving_b = db.session.query(Task).filter_by(name="Driving, run 1", team_id=team_b.id).one()
    assert client.delete(f"/api/v1/tasks/{driving_b.id}", headers=officer).status_code == 204
    assert "teams:\n  - Team A" in exported()
    renamed = client.patch(f"/api/v1/teams/{team_a.id}", json={"name": "Team Z"}, headers=officer)
    assert renamed.status_code == 200, renamed.json
    assert "Team Z" in exported() and "Team A" not in exported()
    # Another process's change, written straight to the database, shows too.
    db.session.execute(sa.update(Task).values(uplink_bits=4242))
    db.session.commit()
    assert "uplink_bits: 4242" in exported() and "uplink_bits: 115200" not in exported()
