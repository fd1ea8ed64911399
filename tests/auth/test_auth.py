"""Logging in and out, sessions, CSRF, failed-login limits, API tokens."""

from __future__ import annotations

import re

from flask import Flask
from sqlalchemy import select

from cloudsim.auth.policy import SYSTEM
from cloudsim.extensions import db
from cloudsim.models import ApiToken, AuditEvent, User
from cloudsim.people.service import update_user
from tests.conftest import PASSWORD, csrf_token, log_in


def test_form_fields_carry_only_the_autocomplete_hints_given(
    app: Flask, people: dict[str, User | None]
) -> None:
    login = app.test_client().get("/login").get_data(as_text=True)
    assert 'autocomplete="username"' in login and 'autocomplete="current-password"' in login
    client = app.test_client()
    log_in(client, people["user_a"])
    account = client.get("/account").get_data(as_text=True)
    assert "<input" in account and 'autocomplete="None"' not in account


def test_login_needs_csrf_and_the_right_password(
    app: Flask, people: dict[str, User | None]
) -> None:
    user = people["user_a"]
    client = app.test_client()
    page = client.get("/login").get_data(as_text=True)
    no_token = client.post("/login", data={"email": user.email, "password": PASSWORD})
    assert no_token.status_code == 400
    wrong = client.post(
        "/login",
        data={"email": user.email, "password": "nope-nope-nope", "csrf_token": csrf_token(page)},
    )
    assert wrong.status_code == 401 and "Wrong e-mail or password" in wrong.get_data(as_text=True)
    ok = client.post(
        "/login",
        data={"email": user.email.upper(), "password": PASSWORD, "csrf_token": csrf_token(page)},
    )
    assert ok.status_code == 302
    cookie = next(c for c in client._cookies.values() if c.key == "session")
    assert cookie.http_only and cookie.same_site == "Lax"
    actions = db.session.scalars(select(AuditEvent.action)).all()
    assert "auth.login_failed" in actions and "auth.login" in actions


def test_a_disabled_account_is_told_so_only_with_the_right_password(
    app: Flask, people: dict[str, User | None]
) -> None:
    user = people["user_a"]
    assert user is not None
    user.active = False
    db.session.commit()
    client = app.test_client()
    token = csrf_token(client.get("/login").get_data(as_text=True))
    wrong = client.post(
        "/login", data={"email": user.email, "password": "nope-nope-nope", "csrf_token": token}
    )
    assert wrong.status_code == 401
    assert "Wrong e-mail or password" in wrong.get_data(as_text=True)
    assert "disabled" not in wrong.get_data(as_text=True)
    right = client.post(
        "/login", data={"email": user.email, "password": PASSWORD, "csrf_token": token}
    )
    assert right.status_code == 403
    assert "Your account is disabled" in right.get_data(as_text=True)
    assert client.get("/account").status_code == 302  # and no session was started


def test_login_redirects_only_to_local_pages(app: Flask, people: dict[str, User | None]) -> None:
    app.config["WTF_CSRF_ENABLED"] = False
    user = people["user_a"]
    for target, expected in (
        ("/account", "/account"),
        ("https://evil.example/", "/"),
        ("//evil.example/x", "/"),
    ):
        client = app.test_client()
        response = client.post(
            f"/login?next={target}", data={"email": user.email, "password": PASSWORD}
        )
        assert response.headers["Location"] == expected


def test_failed_logins_are_limited_per_account(app: Flask, people: dict[str, User | None]) -> None:
    app.config["WTF_CSRF_ENABLED"] = False
    user = people["user_b"]
    client = app.test_client()
    statuses = [
        client.post("/login", data={"email": user.email, "password": "wrong-password!"}).status_code
        for _ in range(6)
    ]
    assert statuses == [401] * 5 + [429]
    # Even the right password is refused until the window passes: that is the point.
    right = client.post("/login", data={"email": user.email, "password": PASSWORD})
    assert right.status_code == 429 and "Too many attempts" in right.get_data(as_text=True)


def test_disabled_user_and_changed_password_end_sessions(
    app: Flask, people: dict[str, User | None]
) -> None:
    app.config["WTF_CSRF_ENABLED"] = False
    user = people["user_a"]
    client = app.test_client()
    log_in(client, user)
    assert client.get("/account").status_code == 200
    update_user(SYSTEM, user.id, password="another long password")
    assert client.get("/account").status_code == 302  # logged out everywhere
    client2 = app.test_client()
    client2.post("/login", data={"email": user.email, "password": "another long password"})
    assert client2.get("/account").status_code == 200
    update_user(SYSTEM, user.id, active=False)
    assert client2.get("/account").status_code == 302
    denied = client2.post("/login", data={"email": user.email, "password": "another long password"})
    assert denied.status_code == 403  # told the account is disabled: the password was right


def test_api_tokens_are_shown_once_stored_hashed_and_revocable(
    app: Flask, people: dict[str, User | None]
) -> None:
    app.config["WTF_CSRF_ENABLED"] = False
    user = people["user_a"]
    client = app.test_client()
    log_in(client, user)
    page = client.post("/account/tokens", data={"name": "laptop"}).get_data(as_text=True)
    token = re.search(r'<code id="new-token">([^<]+)</code>', page).group(1)  # type: ignore[union-attr]
    stored = db.session.scalars(select(ApiToken)).one()
    assert token not in stored.token_hash and stored.prefix == token[:10]
    api = app.test_client()  # no session cookie: the token alone authenticates
    me = api.get("/api/v1/me", headers={"Authorization": f"Bearer {token}"})
    assert me.status_code == 200 and me.json["email"] == user.email
    assert "password_hash" not in me.json
    listing = api.get("/api/v1/tokens", headers={"Authorization": f"Bearer {token}"}).json
    assert token not in str(listing)
    client.post(f"/account/tokens/{stored.id}/revoke")
    assert api.get("/api/v1/me", headers={"Authorization": f"Bearer {token}"}).status_code == 401


def test_session_cookie_does_not_authenticate_the_api(
    app: Flask, people: dict[str, User | None]
) -> None:
    """The API takes tokens only, so a browser session cannot be ridden without CSRF checks."""
    app.config["WTF_CSRF_ENABLED"] = False
    client = app.test_client()
    log_in(client, people["admin"])  # type: ignore[arg-type]
    assert client.get("/api/v1/me").status_code == 401
    assert client.post("/api/v1/teams", json={"name": "Sneaky"}).status_code == 401


def test_openapi_describes_every_api_route(app: Flask) -> None:
    spec = app.test_client().get("/api/v1/openapi.json").json
    paths = set(spec["paths"])
    assert {"/api/v1/teams", "/api/v1/users/{user_id}", "/api/v1/jobs", "/api/v1/me"} <= paths
    assert spec["components"]["securitySchemes"]["bearerAuth"]["scheme"] == "bearer"
    for rule in app.url_map.iter_rules():
        if rule.rule.startswith("/api/v1/") and "openapi" not in rule.rule:
            documented = re.sub(r"<(?:\w+:)?(\w+)>", r"{\1}", rule.rule)
            assert documented in paths, f"{rule.rule} is not in the OpenAPI description"
