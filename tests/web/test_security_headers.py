"""Security headers on every answer, no caching of secrets, private files on disk."""

from __future__ import annotations

import re
import stat
from pathlib import Path

from flask import Flask

import templates
from cloudsim.app import create_app
from cloudsim.config import Config
from cloudsim.models import User
from tests.conftest import log_in, token_for

PAGES = ("/login", "/", "/account", "/users", "/users/new", "/teams", "/jobs", "/tasks", "/runs")


def _assert_hardened(response: object, where: str) -> None:
    headers = response.headers  # type: ignore[attr-defined]
    policy = headers.get("Content-Security-Policy", "")
    assert "frame-ancestors 'none'" in policy and "script-src 'self'" in policy, where
    assert "unsafe-inline" not in policy, where
    assert headers.get("X-Frame-Options") == "DENY", where
    assert headers.get("X-Content-Type-Options") == "nosniff", where
    assert headers.get("Referrer-Policy") == "same-origin", where
    assert headers.get("Cache-Control") == "no-store", where


def test_every_page_and_api_answer_carries_the_headers(
    app: Flask, people: dict[str, User | None]
) -> None:
    client = app.test_client()
    _assert_hardened(client.get("/login"), "/login")
    log_in(client, people["admin"])  # type: ignore[arg-type]
    for path in (*PAGES, "/no-such-page"):
        _assert_hardened(client.get(path), path)
    api = app.test_client()
    _assert_hardened(api.get("/api/v1/me"), "401 from the API")
    _assert_hardened(api.get("/api/v1/me", headers=token_for(people["admin"])), "/api/v1/me")  # type: ignore[arg-type]


def test_pages_that_show_a_secret_once_are_never_stored(
    app: Flask, people: dict[str, User | None]
) -> None:
    app.config["WTF_CSRF_ENABLED"] = False
    client = app.test_client()
    log_in(client, people["officer"])  # type: ignore[arg-type]
    team_id = people["user_a"].team_id  # type: ignore[union-attr]
    created = client.post(
        "/users/new", data={"email": "new@example.org", "role": "user", "team": str(team_id)}
    )
    assert created.status_code == 200 and "not shown again" in created.get_data(as_text=True)
    _assert_hardened(created, "generated password page")
    token = client.post("/account/tokens", data={"name": "laptop"})
    assert 'id="new-token"' in token.get_data(as_text=True)
    _assert_hardened(token, "new token page")
    key = client.post("/account/ssh-keys", data={"generate": "1"})
    assert 'id="new-private-key"' in key.get_data(as_text=True)
    _assert_hardened(key, "generated SSH key page")
    headers = token_for(people["officer"])  # type: ignore[arg-type]
    api = app.test_client()
    _assert_hardened(api.post("/api/v1/tokens", json={"name": "x"}, headers=headers), "API token")
    made = api.post(
        "/api/v1/users", json={"email": "n2@example.org", "team_id": team_id}, headers=headers
    )
    assert made.json["generated_password"]
    _assert_hardened(made, "API generated password")
    key = api.post("/api/v1/me/ssh-keys", json={"generate": True}, headers=headers)
    assert "PRIVATE KEY" in key.json["private_key"]
    _assert_hardened(key, "API generated SSH key")


def test_templates_hold_no_inline_script_or_style() -> None:
    """The CSP allows scripts and styles from /static only; inline ones would be blocked."""
    for template in Path(templates.folder("web")).rglob("*.html"):
        text = template.read_text()
        assert not re.search(r"<script(?![^>]*\b(src=|nonce=))", text), template
        assert not re.search(r"\sstyle=|<style|\son[a-z]+=", text), template


def test_the_instance_folder_and_database_are_private(tmp_path: Path, make_config: object) -> None:
    instance = tmp_path / "instance"
    instance.mkdir(mode=0o755)
    instance.chmod(0o755)  # as an older CloudSim (or a umask of 022) left it
    config: Config = make_config()  # type: ignore[operator]
    app = create_app(config)
    with app.app_context():
        database = Path(app.extensions["sqlalchemy"].engine.url.database)
    assert stat.S_IMODE(config.instance_dir.stat().st_mode) == 0o700
    assert stat.S_IMODE(database.stat().st_mode) == 0o600
