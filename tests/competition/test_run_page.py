"""The run page in a real headless Chromium: its script follows a live run under the CSP."""

from __future__ import annotations

from datetime import timedelta

import pytest
from flask import Flask
from playwright.sync_api import Browser, expect

from cloudsim.extensions import db
from cloudsim.models import Run, RunState, User, utcnow
from tests.competition.support import open_task
from tests.web.test_browser import browser, live_url, log_in_page  # noqa: F401

pytestmark = pytest.mark.browser


def test_the_run_page_follows_a_live_run_without_a_reload(
    app: Flask,
    live_url: str,  # noqa: F811
    browser: Browser,  # noqa: F811
    people: dict[str, User | None],
) -> None:
    user = people["user_a"]
    assert user is not None and user.team_id is not None
    task = open_task(user.team_id)
    run = Run(task_id=task.id, team_id=task.team_id, state=RunState.RUNNING)
    db.session.add(run)
    db.session.commit()
    page = browser.new_context().new_page()
    problems: list[str] = []  # what the CSP blocks is "Refused to ..." on the console
    page.on("console", lambda m: problems.append(m.text) if "Refused" in m.text else None)
    page.on("pageerror", lambda error: problems.append(str(error)))
    log_in_page(page, live_url, user)
    page.goto(f"{live_url}/runs/{run.id}")
    expect(page.locator("#caps-spent")).to_have_text("none")

    spent = (utcnow() - timedelta(seconds=30)).replace(microsecond=0)
    run.score, run.sim_seconds = 2, 12.5
    run.uplink_bits_used, run.uplink_spent_at = task.uplink_bits, spent
    db.session.commit()
    expect(page.locator("#run-score")).to_have_text("2")
    expect(page.locator("#run-time")).to_have_text("12.5")
    expect(page.locator("#uplink-left")).to_have_text("0")
    caps = page.locator("#caps-spent")
    expect(caps).to_have_text(
        f"uplink spent since {spent:%Y-%m-%d %H:%M:%S} UTC (traffic that way is dropped)"
    )
    expect(caps).to_have_class("error")

    # the dashboard's run card follows the same figures
    page.goto(f"{live_url}/")
    card = page.locator(f"#run-card-{run.id}")
    expect(card.locator('[data-live="sim_seconds"]')).to_have_text("12.5")
    run.sim_seconds, run.score = 14.0, 3
    db.session.commit()
    expect(card.locator('[data-live="sim_seconds"]')).to_have_text("14.0")
    expect(card.locator('[data-live="score"]')).to_have_text("3")
    expect(card.locator('[data-live="uplink_left"]')).to_have_text("0")
    assert problems == []
    page.context.close()
