"""The portal's pages as the README promises them: each team its own, officers all, exports."""

from __future__ import annotations

import csv
import io
import json
import re
from pathlib import Path

import pytest
from flask import Flask
from flask.testing import FlaskClient

from cloudsim.extensions import db
from cloudsim.models import RunState, User, utcnow
from cloudsim.portal import views
from tests.conftest import log_in
from tests.portal.support import scored_run, team_instance


def test_a_team_sees_its_own_results_logs_and_cloudsim_and_nothing_of_another(
    app: Flask, people: dict[str, User | None], tmp_path: Path
) -> None:
    user_a, user_b = people["user_a"], people["user_b"]
    assert user_a is not None and user_b is not None
    own = scored_run(user_a.team_id or 0, tmp_path, checkpoints=3, uplink_bytes=500)
    other = scored_run(user_b.team_id or 0, tmp_path, checkpoints=1, uplink_bytes=900)
    team_instance(user_a.team_id or 0, "team-a", "https://198.51.100.7")
    client = app.test_client()
    log_in(client, user_a)

    page = client.get("/portal").get_data(as_text=True)
    assert "https://198.51.100.7" in page
    assert f'data-run="{own.id}"' in page and f'data-run="{other.id}"' not in page
    assert "Team B" not in page
    assert f"/runs/{own.id}/logs/" in page  # its logs, to download
    for url in (
        f"/portal/teams/{user_b.team_id}",
        f"/runs/{other.id}/bandwidth.csv",
        f"/runs/{other.id}",
    ):
        assert client.get(url).status_code == 404, url
    for url in ("/portal/figures", "/portal/figures/uplink-score.csv"):
        body = client.get(url).get_data(as_text=True)
        assert "Team A" in body and "Team B" not in body, url
    assert client.get("/portal/results.csv").status_code == 403


def test_officers_export_every_run_of_the_season(
    app: Flask, people: dict[str, User | None], tmp_path: Path
) -> None:
    user_a, user_b, officer = people["user_a"], people["user_b"], people["officer"]
    assert user_a is not None and user_b is not None and officer is not None
    runs = [
        scored_run(user_a.team_id or 0, tmp_path, checkpoints=2, uplink_bytes=300),
        scored_run(user_b.team_id or 0, tmp_path, checkpoints=4, uplink_bytes=700),
        scored_run(
            user_b.team_id or 0, tmp_path, checkpoints=0, uplink_bytes=100, state=RunState.ERROR
        ),
    ]
    # the first was invalidated by an officer; the second came from team B's instance
    runs[0].invalidated_at, runs[0].invalid_reason = utcnow(), "ran the wrong world"
    runs[0].officer_note = "checked with the team"
    runs[1].instance_id = team_instance(user_b.team_id or 0, "team-b", "https://192.0.2.9").id
    runs[1].remote_run_id = 7
    runs[1].end_reason = '=HYPERLINK("http://e.test")'  # what an instance may send
    db.session.commit()
    client = app.test_client()
    log_in(client, officer)
    index = client.get("/portal").get_data(as_text=True)
    assert 'data-team="Team A"' in index and 'data-team="Team B"' in index

    exported = json.loads(client.get("/portal/results.json").get_data(as_text=True))
    table = list(
        csv.DictReader(io.StringIO(client.get("/portal/results.csv").get_data(as_text=True)))
    )
    assert [r["run_id"] for r in exported] == [r.id for r in runs]
    assert [int(r["run_id"]) for r in table] == [r.id for r in runs]
    for run, row, line in zip(runs, exported, table, strict=True):
        expected = {
            "team": run.team.name,
            "task": run.task.name,
            "world": "vrc_task_1",
            "run_config": run.task.run_config,
            "state": run.state.value,
            "end_reason": run.end_reason,
            "score": run.score,
            "uplink_bits_used": run.uplink_bits_used,
            "uplink_cap_bits": 8_000_000,
            "downlink_bits_used": run.downlink_bits_used,
            "downlink_cap_bits": 64_000_000,
            "source": "team-b" if run is runs[1] else "master",
            "invalidated": run is runs[0],
            "invalid_reason": run.invalid_reason,
            "officer_note": run.officer_note,
            "started_at": run.started_at.isoformat(),
            "finished_at": run.finished_at.isoformat() if run.finished_at else None,
        }
        assert {k: row[k] for k in expected} == expected
        assert {k: line[k] for k in expected if k != "end_reason"} == {
            k: "" if v is None else str(v) for k, v in expected.items() if k != "end_reason"
        }
    # a spreadsheet shows the CSV's text as text, never runs it as a formula
    assert [r["end_reason"] for r in table] == [
        "time_limit",
        "'" + runs[1].end_reason,
        "time_limit",
    ]
    # the figures count only scoring runs: finished and not invalidated
    text = client.get("/portal/figures/uplink-score.csv").get_data(as_text=True)
    assert [int(r["run_id"]) for r in csv.DictReader(io.StringIO(text))] == [runs[1].id]
    page = client.get(f"/portal/teams/{user_a.team_id}").get_data(as_text=True)
    assert "ran the wrong world" in page and "checked with the team" in page


def test_the_figures_page_lists_the_scoring_runs_a_page_at_a_time(
    app: Flask, people: dict[str, User | None], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    user_a, user_b, officer = people["user_a"], people["user_b"], people["officer"]
    assert user_a is not None and user_b is not None and officer is not None
    monkeypatch.setattr(views, "FIGURE_RUNS_PAGE", 2)
    scoring = [
        scored_run(team, tmp_path, checkpoints=1, uplink_bytes=100)
        for team in (user_a.team_id or 0, user_b.team_id or 0, user_b.team_id or 0)
    ]
    scored_run(user_b.team_id or 0, tmp_path, checkpoints=0, uplink_bytes=1, state=RunState.ERROR)
    client, theirs = app.test_client(), app.test_client()
    log_in(client, officer)
    log_in(theirs, user_a)

    def listed(url: str, by: FlaskClient = client) -> tuple[list[int], str]:
        page = by.get(url).get_data(as_text=True)
        table = page.split('id="bandwidth-runs"')[1].split("</table>")[0]
        return [int(n) for n in re.findall(r'href="/runs/(\d+)"', table)], page

    first, page = listed("/portal/figures")
    assert first == [r.id for r in scoring[:2]] and "page 1 of 2" in page
    assert 'href="/portal/figures?page=2"' in page
    second, page = listed("/portal/figures?page=2")
    assert second == [scoring[2].id] and 'href="/portal/figures?page=1"' in page
    assert listed("/portal/figures?page=9")[0] == []  # past the end: an empty page, not a 404
    assert listed("/portal/figures?page=x")[0] == first  # junk: the first page
    # the figures themselves still draw every scoring run, whatever the page
    csv_rows = client.get("/portal/figures/uplink-score.csv").get_data(as_text=True)
    assert len(list(csv.DictReader(io.StringIO(csv_rows)))) == 3
    own, page = listed("/portal/figures", theirs)  # a team user: its own runs only
    assert own == [scoring[0].id] and "page 1 of" not in page
