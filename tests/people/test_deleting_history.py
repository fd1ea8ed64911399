"""Deleting what has a history: a team that ever had a constellation or runs is refused with
409 and the reason (page and API); a user who started runs is deleted, the runs kept."""

from __future__ import annotations

from flask import Flask

from cloudsim.auth.policy import SYSTEM
from cloudsim.extensions import db
from cloudsim.models import Constellation, ConstellationState, Role, Run, RunState, Team, User
from cloudsim.people.service import create_team
from tests.competition.support import open_task
from tests.conftest import csrf_token, log_in, make_user, token_for


def _team_with_a_past(name: str) -> Team:
    team = create_team(SYSTEM, name)
    db.session.add(
        Constellation(
            name=f"{name.lower().replace(' ', '-')}-old",
            kind="vrc",
            provider="local",
            team_id=team.id,
            state=ConstellationState.TERMINATED,
        )
    )
    db.session.commit()
    return team


def test_a_team_that_had_a_constellation_is_refused_with_the_reason(
    app: Flask, people: dict[str, User | None]
) -> None:
    officer = people["officer"]
    assert officer is not None
    team = _team_with_a_past("Gone Team")
    api = app.test_client().delete(f"/api/v1/teams/{team.id}", headers=token_for(officer))
    assert api.status_code == 409, api.get_data(as_text=True)
    assert "1 constellation(s)" in api.json["message"]

    client = app.test_client()
    log_in(client, officer)
    page = client.get(f"/teams/{team.id}").get_data(as_text=True)
    answer = client.post(f"/teams/{team.id}/delete", data={"csrf_token": csrf_token(page)})
    assert answer.status_code == 409
    assert "history" in answer.get_data(as_text=True)
    db.session.expire_all()
    assert db.session.get(Team, team.id) is not None


def test_a_team_with_runs_is_refused_and_a_user_who_started_runs_is_deleted(
    app: Flask, people: dict[str, User | None]
) -> None:
    officer = people["officer"]
    assert officer is not None
    team = create_team(SYSTEM, "Runners")
    starter = make_user(Role.USER, team, "starter@example.org")
    run = Run(
        task_id=open_task(team.id).id,
        team_id=team.id,
        state=RunState.FINISHED,
        started_by_id=starter.id,
    )
    db.session.add(run)
    db.session.commit()

    gone = app.test_client().delete(f"/api/v1/users/{starter.id}", headers=token_for(officer))
    assert gone.status_code in (200, 204), gone.get_data(as_text=True)
    db.session.expire_all()
    kept = db.session.get(Run, run.id)
    assert kept is not None and kept.started_by_id is None  # the run stays, unattributed
    refused = app.test_client().delete(f"/api/v1/teams/{team.id}", headers=token_for(officer))
    assert refused.status_code == 409 and "1 run(s)" in refused.json["message"]
