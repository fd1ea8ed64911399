"""Bad input answers 400/404/409 with a message that says what is wrong, and changes nothing."""

from __future__ import annotations

import pytest
from flask import Flask
from sqlalchemy import func, select

from cloudsim.extensions import db
from cloudsim.models import AuditEvent, Team, User
from tests.conftest import log_in, token_for


def _count(model: type) -> int:
    return db.session.scalar(select(func.count()).select_from(model))  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("method", "path", "body", "status", "message"),
    [
        ("POST", "/api/v1/teams", "{not json", 400, "Invalid JSON"),
        ("POST", "/api/v1/teams", {}, 400, "name"),
        ("POST", "/api/v1/teams", {"name": "   "}, 400, "must not be empty"),
        ("POST", "/api/v1/teams", {"name": "Team A"}, 409, "already exists"),
        ("POST", "/api/v1/teams", {"name": "x" * 81}, 400, "name"),
        ("POST", "/api/v1/users", {"email": "nobody"}, 400, "e-mail"),
        ("POST", "/api/v1/users", {"email": "u@example.org"}, 400, "must belong to a team"),
        ("POST", "/api/v1/users", {"email": "u@example.org", "team_id": 999}, 404, "team 999"),
        ("POST", "/api/v1/users", {"email": "u@example.org", "role": "king"}, 400, "role"),
        (
            "POST",
            "/api/v1/users",
            {"email": "o@example.org", "role": "officer", "team_id": 1},
            400,
            "do not belong to a team",
        ),
        (
            "POST",
            "/api/v1/users",
            {"email": "u@example.org", "team_id": 1, "password": "short"},
            400,
            "at least 10",
        ),
        ("POST", "/api/v1/jobs", {"kind": "format-disk"}, 400, "unknown maintenance job kind"),
        ("POST", "/api/v1/jobs", {"kind": "run.start"}, 400, "unknown maintenance job kind"),
        ("GET", "/api/v1/jobs?state=exploded", None, 400, "state"),
        ("GET", "/api/v1/jobs?page=-1", None, 400, "page"),
        ("GET", "/api/v1/jobs/no-such-job", None, 404, "not found"),
        ("GET", "/api/v1/teams/4242", None, 404, "not found"),
        ("PATCH", "/api/v1/users/4242", {"name": "x"}, 404, "not found"),
        ("DELETE", "/api/v1/tokens/4242", None, 404, "not found"),
        ("GET", "/api/v1/nothing-here", None, 404, "nothing here"),
        (
            "POST",
            "/api/v1/constellations",
            {"name": "x", "kind": "moon"},
            400,
            "unknown constellation kind 'moon' (known: cloudsim, simple, vrc)",
        ),
        (
            "POST",
            "/api/v1/constellations",
            {"name": "Bad Name!", "kind": "vrc"},
            400,
            "constellation name must be",
        ),
        (
            "POST",
            "/api/v1/constellations",
            {"name": "x", "kind": "vrc", "provider": "mars"},
            400,
            "unknown provider 'mars'",
        ),
        ("GET", "/api/v1/constellations/4242", None, 404, "not found"),
    ],
)
def test_api_rejects_bad_input_clearly(
    app: Flask,
    people: dict[str, User | None],
    method: str,
    path: str,
    body: object,
    status: int,
    message: str,
) -> None:
    headers = token_for(people["admin"])  # type: ignore[arg-type]
    before = (_count(Team), _count(User), _count(AuditEvent))
    kwargs: dict[str, object] = {"headers": headers}
    if isinstance(body, str):
        kwargs.update(data=body, content_type="application/json")
    elif body is not None:
        kwargs["json"] = body
    response = app.test_client().open(path, method=method, **kwargs)
    assert response.status_code == status, response.get_data(as_text=True)
    text = response.get_data(as_text=True)
    assert message.lower() in text.lower()
    assert response.json is not None and response.json["code"] == status
    assert (_count(Team), _count(User), _count(AuditEvent)) == before


def test_web_forms_reject_bad_input_and_keep_the_page(
    app: Flask, people: dict[str, User | None]
) -> None:
    app.config["WTF_CSRF_ENABLED"] = False
    client = app.test_client()
    log_in(client, people["officer"])  # type: ignore[arg-type]
    users_before = _count(User)
    response = client.post("/users/new", data={"email": "bad", "role": "user", "team": "1"})
    assert response.status_code == 400 and "invalid e-mail address" in response.get_data(
        as_text=True
    )
    response = client.post(
        "/users/new", data={"email": "o@example.org", "role": "admin", "team": ""}
    )
    assert response.status_code == 400  # officers are not offered the admin role at all
    response = client.post("/teams", data={"name": "team a"})
    assert response.status_code == 409 and "already exists" in response.get_data(as_text=True)
    assert _count(User) == users_before
    assert client.get("/jobs/not-a-job").status_code == 404
    assert client.get("/teams/999").status_code == 404
    assert client.get("/jobs?page=abc").status_code == 200  # a junk page number means page 1


def test_no_route_answers_500_to_garbage(app: Flask, people: dict[str, User | None]) -> None:
    app.config["WTF_CSRF_ENABLED"] = False
    client = app.test_client()
    log_in(client, people["admin"])  # type: ignore[arg-type]
    headers = token_for(people["admin"])  # type: ignore[arg-type]
    garbage = {"name": "\x00" * 3, "email": "@@", "role": ["x"], "team": "abc", "page": "-5"}
    for rule in app.url_map.iter_rules():
        if rule.endpoint == "monitoring.readyz":
            continue  # its 503 is its answer ("not ready": no worker here), checked elsewhere
        if rule.endpoint == "static" or rule.arguments - {
            "team_id",
            "user_id",
            "job_id",
            "token_id",
            "ref",
        }:
            continue
        path = (
            rule.rule.replace("<int:", "<")
            .replace("<team_id>", "1")
            .replace("<user_id>", "99")
            .replace("<job_id>", "x")
            .replace("<token_id>", "99")
            .replace("<ref>", "99")
        )
        for method in rule.methods - {"HEAD", "OPTIONS"}:  # type: ignore[operator]
            if path.startswith("/api/"):
                response = client.open(
                    path, method=method, json=["not", "an", "object"], headers=headers
                )
            else:
                response = client.open(path, method=method, data=garbage)
            assert response.status_code < 500, f"{method} {path}: {response.status_code}"
            db.session.rollback()
