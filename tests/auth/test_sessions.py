"""Browser sessions live on the server: they end at logout and with their account, and what
survives a password change or a disable/enable is exactly what the README says."""

from __future__ import annotations

from datetime import timedelta

from flask import Flask
from flask.testing import FlaskClient
from sqlalchemy import func, select, update

from cloudsim.extensions import db
from cloudsim.models import LoginSession, Role, User, utcnow
from cloudsim.people.service import delete_user, update_user
from tests.conftest import PASSWORD, csrf_token, log_in, make_user, token_for

COOKIE = "session"


def _copy_cookie(source: FlaskClient, target: FlaskClient) -> None:
    cookie = source.get_cookie(COOKIE)
    assert cookie is not None
    target.set_cookie(COOKIE, cookie.value, domain=cookie.domain)


def _log_out(client: FlaskClient) -> None:
    token = csrf_token(client.get("/account").get_data(as_text=True))
    assert client.post("/logout", data={"csrf_token": token}).status_code == 302


def test_a_deleted_users_cookie_does_not_open_the_next_account(
    app: Flask, people: dict[str, User | None]
) -> None:
    victim = make_user(Role.USER, people["user_a"].team)  # type: ignore[union-attr]
    client = app.test_client()
    log_in(client, victim)
    victim_id = victim.id
    delete_user(people["admin"], victim_id)
    officer = make_user(Role.OFFICER)
    assert officer.id == victim_id  # SQLite hands the id out again: the attack's premise
    assert client.get("/users").status_code == 302  # to the login page, not the officer's list
    assert client.get("/account").status_code == 302


def test_a_copied_cookie_stops_working_at_logout(
    app: Flask, people: dict[str, User | None]
) -> None:
    browser, thief = app.test_client(), app.test_client()
    log_in(browser, people["user_a"])  # type: ignore[arg-type]
    _copy_cookie(browser, thief)
    assert thief.get("/account").status_code == 200  # the same browser, as far as CloudSim sees
    _log_out(browser)
    assert thief.get("/account").status_code == 302
    assert db.session.scalar(select(func.count()).select_from(LoginSession)) == 0


def test_the_cookie_names_no_account_id(app: Flask, people: dict[str, User | None]) -> None:
    client = app.test_client()
    user = people["user_a"]
    log_in(client, user)  # type: ignore[arg-type]
    with client.session_transaction() as session:
        key = session["_user_id"]
    assert str(user.id) not in key.split(":")  # type: ignore[union-attr]
    assert len(key) >= 40


def test_sessions_end_on_the_server_after_their_lifetime(
    app: Flask, people: dict[str, User | None]
) -> None:
    client = app.test_client()
    log_in(client, people["user_a"])  # type: ignore[arg-type]
    hours = app.config["CLOUDSIM"].session_hours
    long_ago = utcnow() - timedelta(hours=hours + 1)
    db.session.execute(update(LoginSession).values(created_at=long_ago))
    db.session.commit()
    assert client.get("/account").status_code == 302
    log_in(client, people["user_a"])  # type: ignore[arg-type]
    assert db.session.scalar(select(func.count()).select_from(LoginSession)) == 1  # old one gone


def test_a_password_change_ends_other_sessions_and_keeps_tokens(
    app: Flask, people: dict[str, User | None]
) -> None:
    user = people["user_a"]
    here, elsewhere = app.test_client(), app.test_client()
    log_in(here, user)  # type: ignore[arg-type]
    log_in(elsewhere, user)  # type: ignore[arg-type]
    headers = token_for(user)  # type: ignore[arg-type]
    page = here.get("/account").get_data(as_text=True)
    response = here.post(
        "/account/password",
        data={
            "current": PASSWORD,
            "new": "a brand new password",
            "confirm": "a brand new password",
            "csrf_token": csrf_token(page),
        },
    )
    assert response.status_code == 302, response.get_data(as_text=True)
    assert here.get("/account").status_code == 200  # this browser stays logged in
    assert elsewhere.get("/account").status_code == 302
    assert app.test_client().get("/api/v1/me", headers=headers).status_code == 200


def test_disabling_ends_sessions_and_revokes_tokens_for_good(
    app: Flask, people: dict[str, User | None]
) -> None:
    user = people["user_a"]
    assert user is not None
    client = app.test_client()
    log_in(client, user)
    headers = token_for(user)
    update_user(people["officer"], user.id, active=False)
    assert client.get("/account").status_code == 302
    assert app.test_client().get("/api/v1/me", headers=headers).status_code == 401
    update_user(people["officer"], user.id, active=True)
    assert app.test_client().get("/api/v1/me", headers=headers).status_code == 401
    assert client.get("/account").status_code == 302
    log_in(client, user)  # the password still works: only the old ways in are gone
    assert client.get("/account").status_code == 200
