"""The Tasks and Runs pages show a season a page at a time, as the README says: following the
page links shows every task and every run exactly once."""

from __future__ import annotations

import re

from flask import Flask, current_app
from flask.testing import FlaskClient

from cloudsim.competition.artifacts import LogStore
from cloudsim.extensions import db
from cloudsim.models import Role
from tests.conftest import log_in, make_user
from tests.support.season import add_season, new_teams


def follow(client: FlaskClient, url: str, link: str, row: str) -> list[list[str]]:
    """Return the rows (by the pattern `row`) of each page, following the link named `link`."""
    pages = []
    while url:
        response = client.get(url)
        assert response.status_code == 200
        html = response.get_data(as_text=True)
        pages.append(re.findall(row, html))
        after = re.search(rf'<a href="([^"]+)">{link}</a>', html)
        url = after[1].replace("&amp;", "&") if after else ""
    return pages


def test_tasks_and_runs_pages_show_a_season_page_by_page(app: Flask) -> None:
    team = new_teams(1)[0]
    store = LogStore(current_app.config["CLOUDSIM"])
    add_season(store, [team], "x", users=0, runs=120, jobs=0, events=1, log_seconds=1)
    db.session.commit()
    client = app.test_client()
    log_in(client, make_user(Role.OFFICER))

    runs = follow(client, "/runs", "Older →", r'<tr><td><a href="/runs/(\d+)">')
    assert [len(page) for page in runs] == [50, 50, 20]
    assert len({run for page in runs for run in page}) == 120

    tasks = follow(client, "/tasks", "Later →", r'<tr data-task="(\d+)">')
    assert [len(page) for page in tasks] == [100, 21]  # a task per run, and one open now
    assert len({task for page in tasks for task in page}) == 121
