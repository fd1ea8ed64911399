"""Input built to break parsers answers 4xx with a reason, changes nothing and logs no traceback.

Each case here answered 500 before the input was bounded in one place (cloudsim/web/inputs.py).
"""

from __future__ import annotations

import json

import pytest
from flask import Flask

from cloudsim.models import User
from tests.conftest import log_in, token_for
from tests.web.fuzz import watched_log

HUGE = str(2**64 + 1)  # beyond any database integer
THOUSANDS = "7" * 5000  # past Python's own 4,300-digit limit


def _api(app: Flask, user: User, method: str, path: str, body: str | None = None) -> object:
    kwargs: dict[str, object] = {"headers": token_for(user)}
    if body is not None:
        kwargs.update(data=body, content_type="application/json")
    return app.test_client().open(path, method=method, **kwargs)


@pytest.mark.parametrize(
    ("method", "path", "body", "status"),
    [
        ("GET", f"/api/v1/teams/{HUGE}", None, 404),
        ("PATCH", f"/api/v1/users/{HUGE}", '{"name": "x"}', 404),
        ("GET", f"/api/v1/constellations/{HUGE}", None, 404),
        ("GET", f"/api/v1/runs/{HUGE}", None, 404),
        ("DELETE", f"/api/v1/tasks/{HUGE}", None, 404),
        ("GET", f"/api/v1/constellations/1/vpn-bundle?user_id={HUGE}", None, 400),
        ("POST", "/api/v1/users", json.dumps({"email": "a@example.org", "team_id": 10**30}), 400),
        ("POST", "/api/v1/teams", '{"name": ' + THOUSANDS + "}", 400),
        ("POST", "/api/v1/teams", '{"name": "x", "n": ' + THOUSANDS + "}", 400),
        ("POST", "/api/v1/teams", "[" * 50_000 + "]" * 50_000, 400),
        ("POST", "/api/v1/teams", '{"name": ' + "[" * 40 + "]" * 40 + "}", 400),
        ("POST", "/api/v1/teams", '{"name": "lone \\ud800 surrogate"}', 400),
        ("POST", "/api/v1/teams", '{"name": NaN}', 400),
        (
            "POST",
            "/api/v1/tasks",
            json.dumps(
                {
                    "name": "edge",
                    "world": "vrc_task_1",
                    "start": "0001-01-01 00:00",
                    "stop": "0001-01-01 05:00",
                    "time_zone": "Asia/Tokyo",
                }
            ),
            400,
        ),
        (
            "POST",
            "/api/v1/tasks",
            json.dumps(
                {
                    "name": "edge",
                    "world": "vrc_task_1",
                    "start": "9999-12-31 20:00",
                    "stop": "9999-12-31 23:00",
                    "time_zone": "America/New_York",
                }
            ),
            400,
        ),
        (
            "POST",
            "/api/v1/tasks",
            json.dumps(
                {"name": "e", "world": "vrc_task_1", "start": "a", "stop": "b", "order": 10**19}
            ),
            400,
        ),
        (
            "POST",
            "/api/v1/schedule",
            json.dumps(
                {
                    "yaml": "tasks: [{name: d, world: vrc_task_1, "
                    "start: 2030-02-30, stop: 2031-01-01}]"
                }
            ),
            400,
        ),
        (
            "POST",
            "/api/v1/schedule",
            json.dumps(
                {
                    "yaml": "tasks: [{name: d, world: vrc_task_1, start: 2030-01-01, "
                    f"stop: 2031-01-01, config: {THOUSANDS}}}]"
                }
            ),
            400,
        ),
        (
            "POST",
            "/api/v1/schedule",
            json.dumps({"yaml": "tasks: " + "[" * 5000 + "]" * 5000}),
            400,
        ),
    ],
)
def test_api_refuses_hostile_input(
    app: Flask,
    people: dict[str, User | None],
    method: str,
    path: str,
    body: str | None,
    status: int,
) -> None:
    with watched_log() as log:
        response = _api(app, people["admin"], method, path, body)  # type: ignore[arg-type]
    assert response.status_code == status, response.get_data(as_text=True)[:300]  # type: ignore[attr-defined]
    assert response.json["message"]  # type: ignore[attr-defined]
    assert not log.records, log.report()


def test_a_date_only_yaml_time_means_midnight_in_the_zone(
    app: Flask, people: dict[str, User | None]
) -> None:
    text = (
        "time_zone: Asia/Tokyo\ntasks: [{name: Dates, world: vrc_task_1, "
        "start: 2030-01-01, stop: 2030-01-02}]"
    )
    with watched_log() as log:
        response = _api(
            app, people["admin"], "POST", "/api/v1/schedule", json.dumps({"yaml": text})
        )  # type: ignore[arg-type]
    assert response.status_code == 201, response.get_data(as_text=True)  # type: ignore[attr-defined]
    assert response.json[0]["window_start"].startswith("2029-12-31T15:00")  # type: ignore[attr-defined]
    assert not log.records, log.report()


def test_pages_far_past_the_end_are_empty(app: Flask, people: dict[str, User | None]) -> None:
    client = app.test_client()
    log_in(client, people["officer"])  # type: ignore[arg-type]
    with watched_log() as log:
        for path in (f"/jobs?page={HUGE}", f"/audit?page={HUGE}", f"/jobs?page={THOUSANDS}"):
            assert client.get(path).status_code == 200, path
        api = app.test_client()
        headers = token_for(people["officer"])  # type: ignore[arg-type]
        response = api.get(f"/api/v1/jobs?page={2**62}", headers=headers)
        assert response.status_code == 200 and response.json == []
        response = api.get(f"/api/v1/jobs?page={HUGE}", headers=headers)
        assert response.status_code == 200 and response.json == []
        response = api.get(f"/api/v1/jobs?page={THOUSANDS}", headers=headers)
        assert response.status_code == 400
    assert not log.records, log.report()


def test_web_forms_refuse_hostile_input(app: Flask, people: dict[str, User | None]) -> None:
    app.config["WTF_CSRF_ENABLED"] = False
    client = app.test_client()
    log_in(client, people["officer"])  # type: ignore[arg-type]
    task = {
        "name": "Hostile",
        "team": "all",
        "world": "vrc_task_1",
        "run_config": "1",
        "time_zone": "Asia/Tokyo",
        "window_start": "2030-01-01T09:00",
        "window_stop": "2030-01-01T12:00",
        "timeout_s": "60",
        "latency_ms": "250",
        "uplink_bits": "1000",
        "downlink_bits": "1000",
        "order": "0",
    }
    with watched_log() as log:
        for field, value in (
            ("order", HUGE),
            ("uplink_bits", THOUSANDS),
            ("run_config", "9" * 30),
            ("window_start", "0001-01-01T00:00"),
        ):
            response = client.post("/tasks", data={**task, field: value})
            assert response.status_code == 400, (field, response.status_code)
        assert client.get(f"/constellations/1/vpn-bundle?user_id={HUGE}").status_code in (400, 404)
        assert client.get(f"/teams/{HUGE}").status_code == 404
    assert not log.records, log.report()


def test_an_oversized_body_from_a_logged_in_user_gets_the_error_page(
    app: Flask, people: dict[str, User | None]
) -> None:
    client = app.test_client()
    log_in(client, people["officer"])  # type: ignore[arg-type]
    with watched_log() as log:
        response = client.post("/teams", data={"name": "x" * (3 * 1024 * 1024)})
        api = app.test_client().post(
            "/api/v1/teams",
            data="x" * (3 * 1024 * 1024),
            content_type="application/json",
            headers=token_for(people["officer"]),  # type: ignore[arg-type]
        )
    assert response.status_code == 413
    assert "too large" in response.get_data(as_text=True)
    assert "Log out" in response.get_data(as_text=True)  # the full page, as the user
    assert api.status_code == 413
    assert not log.records, log.report()


def test_a_duplicate_non_ascii_team_name_is_a_conflict(
    app: Flask, people: dict[str, User | None]
) -> None:
    """SQLite's lower() folds ASCII only: the database's unique index decides, as a 409."""
    with watched_log() as log:
        first = _api(app, people["officer"], "POST", "/api/v1/teams", '{"name": "Équipe"}')  # type: ignore[arg-type]
        again = _api(app, people["officer"], "POST", "/api/v1/teams", '{"name": "Équipe"}')  # type: ignore[arg-type]
    assert first.status_code == 201  # type: ignore[attr-defined]
    assert again.status_code == 409 and "already exists" in again.json["message"]  # type: ignore[attr-defined]
    assert not log.records, log.report()
