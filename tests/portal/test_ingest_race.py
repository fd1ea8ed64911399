"""The same run record sent twice at the same instant (an instance's retry overtaking its first
try): the request that loses the race answers the run the other one stored, never a 500 nor a
refusal. The race is set up without threads: the other request's run is stored (committed, in
its own session) after this request looked for it and found nothing. Only the same instance's
same run is a twin: another run of the task is still refused."""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator
from typing import Any

import pytest
from flask import Flask
from sqlalchemy import func, select

from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import Constellation, PortalRefusal, Role, Run, TeamInstance
from cloudsim.people.service import create_team
from cloudsim.portal import ingest
from cloudsim.portal.credentials import upload_token
from tests.conftest import csrf_token, log_in, make_user, running_app, token_for
from tests.portal.support import uploader
from tests.support.servers import PostgresServer

URL = "/api/v1/portal/ingest/runs/7"
_databases = itertools.count(1)


@pytest.fixture(params=["sqlite", "postgres"])
def master(request: pytest.FixtureRequest, make_config: Callable[..., Config]) -> Iterator[Flask]:
    url = None
    if request.param == "postgres":
        server: PostgresServer = request.getfixturevalue("postgres_server")
        url = server.create_database(f"cloudsim_portal_race_{next(_databases)}")
    with running_app(make_config(url, portal_url="https://127.0.0.1:5443/")) as app:
        yield app


# finished: the twin is seen by the one-finished-run-per-task check; error: by the unique index
@pytest.mark.parametrize("state", ["finished", "error"])
def test_a_run_sent_twice_at_once_is_stored_once_and_both_answer_it(
    master: Flask, state: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    team = create_team(SYSTEM, "Team A")
    token, record = uploader(team, b"", state=state)
    client = master.test_client()
    first = client.put(URL, json=record, headers=token)
    assert first.status_code == 200, first.json
    looked, missed = ingest.uploaded_run, [None]

    def late(*args: Any) -> Run | None:
        return missed.pop() if missed else looked(*args)  # the twin arrived after the 1st look

    monkeypatch.setattr(ingest, "uploaded_run", late)
    second = client.put(URL, json=record, headers=token)
    assert second.status_code == 200, second.json
    assert second.json == first.json
    monkeypatch.undo()
    db.session.rollback()
    assert db.session.scalar(select(func.count()).select_from(Run)) == 1
    assert db.session.scalar(select(func.count()).select_from(PortalRefusal)) == 0


def test_the_twin_check_still_refuses_another_finished_run_of_the_task(master: Flask) -> None:
    team = create_team(SYSTEM, "Team A")
    token, record = uploader(team, b"")
    client = master.test_client()
    first = client.put(URL, json=record, headers=token)
    assert first.status_code == 200, first.json
    # the same remote id from another instance of the team, and another run of this instance
    other = TeamInstance(
        name="ti-a2",
        team=team,
        constellation=Constellation(name="ti-a2", kind="cloudsim", provider="local"),
    )
    db.session.add(other)
    db.session.commit()
    theirs = {"Authorization": f"Bearer {upload_token(other)}"}
    for url, headers in ((URL, theirs), (URL.replace("/7", "/8"), token)):
        refused = client.put(url, json=record, headers=headers)
        assert refused.status_code == 403, refused.json
        assert "already has a finished run" in refused.json["message"]
    db.session.rollback()
    assert db.session.scalar(select(func.count()).select_from(Run)) == 1


def test_two_finished_runs_of_one_task_at_once_store_one(
    master: Flask, monkeypatch: pytest.MonkeyPatch
) -> None:
    team = create_team(SYSTEM, "Team A")
    token, record = uploader(team, b"")
    client = master.test_client()
    assert client.put(URL, json=record, headers=token).status_code == 200
    checked, missed = ingest._check_once, [None]

    def late(*args: Any) -> Run | None:
        return missed.pop() if missed else checked(*args)  # the other run was stored meanwhile

    monkeypatch.setattr(ingest, "_check_once", late)
    refused = client.put(URL.replace("/7", "/8"), json=record, headers=token)
    assert refused.status_code == 403, refused.json
    assert "already has a finished run" in refused.json["message"]
    monkeypatch.undo()
    db.session.rollback()
    assert db.session.scalar(select(func.count()).select_from(Run)) == 1
    assert db.session.scalar(select(func.count()).select_from(PortalRefusal)) == 1


def test_a_run_is_counted_again_only_while_no_other_run_of_its_task_counts(master: Flask) -> None:
    team = create_team(SYSTEM, "Team A")
    token, record = uploader(team, b"")
    client = master.test_client()
    officer = token_for(make_user(Role.OFFICER))
    first = client.put(URL, json=record, headers=token).json["run_id"]
    review = f"/api/v1/runs/{first}/review"
    invalidate = {"invalidated": True, "reason": "ran the wrong world"}
    assert client.patch(review, json=invalidate, headers=officer).status_code == 200
    second = client.put(URL.replace("/7", "/8"), json=record, headers=token)
    assert second.status_code == 200, second.json  # the task's counted run now
    counts = f"run {second.json['run_id']} of the same task counts"
    again = client.patch(review, json={"invalidated": False}, headers=officer)
    assert again.status_code == 409 and counts in again.json["message"]
    browser = master.test_client()  # the run page's review form, as an officer submits it
    log_in(browser, make_user(Role.OFFICER))
    page = browser.get(f"/runs/{first}").get_data(as_text=True)
    form = {"csrf_token": csrf_token(page), "note": "", "reason": ""}  # Invalidated unticked
    shown = browser.post(f"/runs/{first}/review", data=form, follow_redirects=True)
    assert shown.status_code == 200 and counts in shown.get_data(as_text=True)
    db.session.expire_all()
    assert db.session.get(Run, first).invalid_reason == "ran the wrong world"  # unchanged
    swap = {"invalidated": True, "reason": "swapped"}
    url = f"/api/v1/runs/{second.json['run_id']}/review"
    assert client.patch(url, json=swap, headers=officer).status_code == 200
    counted = client.patch(review, json={"invalidated": False}, headers=officer)
    assert counted.status_code == 200 and counted.json["invalidated_at"] is None
