"""A real headless Chromium: an officer creates a team and a user; the user sees only their team."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from flask import Flask
from playwright.sync_api import Browser, Page, expect, sync_playwright
from werkzeug.serving import make_server

from cloudsim.extensions import db
from cloudsim.models import Constellation, User
from tests.conftest import PASSWORD

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-quic",
]
# WebGL without a GPU (the 3D viewer): SwiftShader, which Chromium enables only when told to
WEBGL_ARGS = [a for a in CHROMIUM_ARGS if a != "--disable-gpu"] + [
    "--use-gl=angle",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
]

pytestmark = pytest.mark.browser


@contextmanager
def webgl_chromium() -> Iterator[Browser]:
    """Start a headless Chromium that draws WebGL in software."""
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=WEBGL_ARGS)
        yield browser
        browser.close()


def log_in_page(page: Page, base: str, user: User) -> None:
    """Log a user in through the login form."""
    _log_in(page, base, user.email, PASSWORD)


@pytest.fixture
def live_url(app: Flask) -> Iterator[str]:
    server = make_server("127.0.0.1", 0, app, threaded=True)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_port}"
    server.shutdown()
    thread.join()


@pytest.fixture(scope="module")  # not longer: other modules start their own Playwright
def browser() -> Iterator[Browser]:
    if not Path(CHROMIUM).exists():
        pytest.fail(f"{CHROMIUM} is missing: install the Debian package chromium (make install)")
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield browser
        browser.close()


def _log_in(page: Page, base: str, email: str, password: str) -> None:
    page.goto(f"{base}/login")
    page.get_by_label("E-mail").fill(email)
    page.get_by_label("Password").fill(password)
    page.get_by_role("button", name="Log in").click()


def test_officer_creates_team_and_user_who_sees_only_their_team(
    app: Flask,
    live_url: str,
    browser: Browser,
    people: dict[str, User | None],
    tmp_path: Path,
) -> None:
    other_team = people["user_b"].team  # type: ignore[union-attr]
    db.session.add(
        Constellation(name="secret-b", kind="vrc", provider="local", team_id=other_team.id)
    )
    db.session.commit()
    context = browser.new_context()
    page = context.new_page()

    _log_in(page, live_url, people["officer"].email, PASSWORD)  # type: ignore[union-attr]
    expect(page.get_by_role("heading", name="Officer dashboard")).to_be_visible()
    page.get_by_role("link", name="Teams").click()
    page.get_by_label("Team name").fill("Rovers")
    page.get_by_role("button", name="Create team").click()
    expect(page.get_by_role("heading", name="Team Rovers")).to_be_visible()
    page.get_by_role("link", name="Users").click()
    page.get_by_role("link", name="New user").click()
    page.get_by_label("E-mail").fill("rover@example.org")
    page.get_by_label("Team").select_option(label="Rovers")
    page.get_by_role("button", name="Create user").click()
    password = page.locator("#generated-password").inner_text()
    assert len(password) >= 16
    page.get_by_role("button", name="Log out").click()
    expect(page.get_by_text("You are logged out.")).to_be_visible()

    _log_in(page, live_url, "rover@example.org", password)
    expect(page.get_by_role("heading", name="Team Rovers")).to_be_visible()
    page.screenshot(path=str(tmp_path / "user-dashboard.png"))
    nav = page.get_by_role("navigation", name="Main")
    expect(nav.get_by_role("link", name="My team")).to_be_visible()
    expect(nav.get_by_role("link", name="Teams")).to_have_count(0)
    assert "secret-b" not in page.content() and other_team.name not in page.content()
    page.goto(f"{live_url}/teams/{other_team.id}")
    expect(page.get_by_role("heading", name="404")).to_be_visible()
    page.goto(f"{live_url}/users")
    expect(page.get_by_role("heading", name="403")).to_be_visible()
    context.close()


def test_the_pages_a_newcomer_meets_first(
    app: Flask, live_url: str, browser: Browser, people: dict[str, User | None]
) -> None:
    """No request fails (the favicon included), the launch form offers a vrc, a job without an
    error shows no Error row, and every page says which CloudSim it is."""
    from cloudsim import __version__
    from cloudsim.models import Job, JobState

    job = Job(id="0" * 36, kind="diagnostics", state=JobState.SUCCEEDED, params={})
    db.session.add(job)
    db.session.commit()
    context = browser.new_context()
    page = context.new_page()
    failed: list[str] = []
    page.on("response", lambda r: failed.append(f"{r.status} {r.url}") if r.status >= 400 else None)
    page.on("console", lambda m: failed.append(m.text) if m.type == "error" else None)

    _log_in(page, live_url, people["admin"].email, PASSWORD)  # type: ignore[union-attr]
    page.get_by_role("link", name="Constellations").click()
    expect(page.get_by_label("Kind")).to_have_value("vrc")
    expect(page.locator("footer")).to_have_text(f"CloudSim {__version__}")
    page.goto(f"{live_url}/jobs/{job.id}")
    expect(page.get_by_text("Error", exact=True)).to_be_hidden()
    page.wait_for_load_state("networkidle")
    assert failed == []
    context.close()
