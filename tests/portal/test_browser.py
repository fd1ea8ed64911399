"""The portal in a real headless Chromium: the figures' numbers are the logs', the leaderboard
follows arriving runs by the VRC rules without a reload."""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from flask import Flask, current_app
from playwright.sync_api import Browser, Page, expect

from cloudsim.competition.artifacts import LogStore
from cloudsim.competition.plots import moving_average
from cloudsim.extensions import db
from cloudsim.models import Run, User, utcnow
from tests.portal.support import scored_run
from tests.web.test_browser import browser, live_url, log_in_page  # noqa: F401

pytestmark = pytest.mark.browser


def _log(run: Run, filename: str) -> list[dict[str, Any]]:
    """Return a stored log's JSON lines, read back from the log store."""
    artifact = next(a for a in run.artifacts if a.filename == filename)
    store = LogStore(current_app.config["CLOUDSIM"])
    return [json.loads(line) for line in store.lines(artifact.location) if line.strip()]


@dataclass(frozen=True)
class Logged:
    """What the figures must show of a run, computed from its logs alone."""

    used: int
    cap: int
    score: int
    per_second: list[int]


def _from_logs(run: Run) -> Logged:
    bandwidth = _log(run, "bandwidth.jsonl")
    armed = next(line for line in bandwidth if line.get("event") == "armed")
    up = [int(line["bytes"]) * 8 for line in bandwidth if line.get("direction") == "uplink"]
    checkpoints = [e for e in _log(run, "score.jsonl") if e["event"] == "checkpoint"]
    return Logged(sum(up), int(armed["caps_bits"]["uplink"]), len(checkpoints), up)


def _page(browser: Browser, base: str, user: User) -> Page:  # noqa: F811
    page = browser.new_context(accept_downloads=True).new_page()
    problems: list[str] = []
    page.on("console", lambda m: problems.append(m.text) if "Refused" in m.text else None)
    page.on("pageerror", lambda error: problems.append(str(error)))
    page.problems = problems  # type: ignore[attr-defined]
    log_in_page(page, base, user)
    return page


def _people(people: dict[str, User | None]) -> tuple[User, User, User]:
    user_a, user_b, officer = people["user_a"], people["user_b"], people["officer"]
    assert user_a and user_b and officer
    return user_a, user_b, officer


def _csv(page: Page, link: str) -> list[dict[str, str]]:
    with page.expect_download() as info:
        page.get_by_role("link", name=link).first.click()
    return list(csv.DictReader(io.StringIO(Path(info.value.path()).read_text())))


def test_the_figures_draw_the_logs_numbers_and_their_csv_hold_the_same(
    app: Flask,
    live_url: str,  # noqa: F811
    browser: Browser,  # noqa: F811
    people: dict[str, User | None],
    tmp_path: Path,
) -> None:
    user_a, user_b, officer = _people(people)
    runs = [
        scored_run(user_a.team_id or 0, tmp_path, checkpoints=3, uplink_bytes=500),
        scored_run(
            user_a.team_id or 0, tmp_path, checkpoints=5, uplink_bytes=2000, uplink_cap=115_200 * 8
        ),
        scored_run(
            user_b.team_id or 0, tmp_path, checkpoints=1, uplink_bytes=9000, uplink_cap=29_491_200
        ),
    ]
    expected = {run.id: _from_logs(run) for run in runs}
    page = _page(browser, live_url, officer)
    page.goto(f"{live_url}/portal/figures")

    points = page.locator("#uplink-score circle")
    expect(points).to_have_count(3)
    for n in range(3):
        point = points.nth(n)
        expect(point).to_be_visible()
        logged = expected[int(point.get_attribute("data-run") or 0)]
        assert float(point.get_attribute("data-x") or 0) == logged.used
        assert float(point.get_attribute("data-y") or 0) == logged.score
    caps = page.locator("#uplink-score line.cap")
    assert sorted(float(c.get_attribute("data-cap") or 0) for c in caps.all()) == sorted(
        float(r.cap) for r in expected.values()
    )
    assert all(c.get_attribute("stroke-dasharray") for c in caps.all())  # dotted

    banked: dict[str, list[float]] = {}
    for run in runs:  # the running total of (cap - used) over each team's runs, in order
        total = banked.setdefault(run.team.name, [])
        left = float(expected[run.id].cap - expected[run.id].used)
        total.append((total[-1] if total else 0.0) + left)
    for team, totals in banked.items():
        line = page.locator(f"#bits-banked polyline[data-series='{team}']")
        expect(page.locator(f"#bits-banked circle[data-series='{team}']")).to_have_count(
            len(totals)
        )
        expect(page.locator(f"#bits-banked circle[data-series='{team}']").last).to_be_visible()
        assert [float(v) for v in (line.get_attribute("data-values") or "").split()] == totals

    rows = _csv(page, "uplink-score.csv")
    assert {(int(r["run_id"]), int(r["uplink_bits_used"]), int(r["score"])) for r in rows} == {
        (run_id, r.used, r.score) for run_id, r in expected.items()
    }
    rows = _csv(page, "bits-banked.csv")
    assert {r["team"]: [] for r in rows}.keys() == banked.keys()
    for team, totals in banked.items():
        assert [float(r["cumulative_bits_banked"]) for r in rows if r["team"] == team] == totals

    # per run (Fig. 6/7): the run page draws it; its CSV holds the 2 s and 10 s averages
    shown = runs[1]
    page.goto(f"{live_url}/runs/{shown.id}")
    expect(page.locator("svg[aria-label='Uplink bandwidth'] polyline")).to_have_count(2)
    rows = [r for r in _csv(page, "Bandwidth as CSV") if r["direction"] == "uplink"]
    per_second = [float(v) for v in expected[shown.id].per_second]
    assert [float(r["bits"]) for r in rows] == per_second
    for window in (2, 10):
        averages = [round(v, 3) for v in moving_average(per_second, window)]
        assert [float(r[f"average_{window}s"]) for r in rows] == averages
    assert page.problems == []  # type: ignore[attr-defined]
    page.context.close()


def test_the_leaderboard_follows_arriving_runs_and_breaks_a_tie_by_bits(
    app: Flask,
    live_url: str,  # noqa: F811
    browser: Browser,  # noqa: F811
    people: dict[str, User | None],
    tmp_path: Path,
) -> None:
    user_a, user_b, _ = _people(people)
    # equal checkpoints: team B used fewer of its uplink bits, so it ranks first
    scored_run(user_a.team_id or 0, tmp_path, checkpoints=4, uplink_bytes=3000)
    scored_run(user_b.team_id or 0, tmp_path, checkpoints=4, uplink_bytes=1000)
    page = _page(browser, live_url, user_a)
    page.goto(f"{live_url}/leaderboard")
    rows = page.locator("#leaderboard tbody tr")
    expect(rows.nth(0)).to_have_attribute("data-team", "Team B")
    expect(rows.nth(1).locator(".rank")).to_have_text("2")

    late = scored_run(user_a.team_id or 0, tmp_path, checkpoints=1, uplink_bytes=100)  # arrives
    expect(rows.nth(0)).to_have_attribute("data-team", "Team A", timeout=10_000)
    expect(rows.nth(0).locator(".checkpoints")).to_have_text("5")
    expect(rows.nth(0).locator(".runs")).to_have_text("2")
    expect(rows.nth(1).locator(".rank")).to_have_text("2")

    late.invalidated_at = utcnow()  # an officer invalidates it: it no longer counts
    db.session.commit()
    expect(rows.nth(0)).to_have_attribute("data-team", "Team B", timeout=10_000)
    expect(rows.nth(1).locator(".invalidated")).to_have_text("1 run(s) invalidated")
    assert page.problems == []  # type: ignore[attr-defined]
    page.context.close()
