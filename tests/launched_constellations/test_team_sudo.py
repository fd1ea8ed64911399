"""The team-sudo toggle as a stranger uses it: the page's button really submitted, the API
called with the documented body; each change audited and pushed. One made while the
constellation is still launching is pushed once it is ready: on local hosts, in
test_local_launch.py (beside a second launch, not a launch of its own)."""

from __future__ import annotations

import re

from flask import Flask
from flask.testing import FlaskClient
from sqlalchemy import func, select

from cloudsim.auth.policy import SYSTEM
from cloudsim.extensions import db
from cloudsim.launched_constellations import service
from cloudsim.models import AuditEvent, Constellation, User
from tests.competition.support import ready_constellation
from tests.conftest import csrf_token, log_in, token_for
from tests.launched_constellations.conftest import access_refreshes


def _constellation(team_id: int, kind: str = "vrc") -> Constellation:
    """Launch one (no worker takes the job) and mark it ready, as its launch would."""
    constellation, _ = service.launch(
        SYSTEM, name=f"sudo-{kind}", kind=kind, provider="local", team_id=team_id
    )
    db.session.commit()
    ready_constellation(constellation.id)
    return constellation


def _count(model: type, *where: object) -> int:
    db.session.expire_all()
    return int(db.session.scalar(select(func.count()).select_from(model).where(*where)) or 0)


def _refreshes(constellation: Constellation) -> int:
    return len(access_refreshes(constellation.id))


def test_an_officer_lets_the_team_use_sudo_with_the_page_button(
    app: Flask, client: FlaskClient, people: dict[str, User | None]
) -> None:
    constellation = _constellation(people["user_a"].team_id)  # type: ignore[union-attr,arg-type]
    log_in(client, people["officer"])  # type: ignore[arg-type]
    page = client.get(f"/constellations/{constellation.id}").get_data(as_text=True)
    assert re.search(r'id="team-sudo">not allowed<', page)
    action = re.search(r'action="([^"]*team-sudo[^"]*)"', page)
    assert action is not None, "the page offers no team-sudo button"
    response = client.post(action.group(1), data={"csrf_token": csrf_token(page)})
    assert response.status_code == 302
    page = client.get(f"/constellations/{constellation.id}").get_data(as_text=True)
    assert re.search(r'id="team-sudo">allowed<', page)
    assert "Take sudo away from the team" in page
    assert _refreshes(constellation) == 1  # pushed to the field computers at once
    assert _count(AuditEvent, AuditEvent.action == "constellation.team_sudo") == 1


def test_the_api_takes_the_documented_body_and_refuses_bad_input(
    app: Flask, people: dict[str, User | None]
) -> None:
    team_id = people["user_a"].team_id  # type: ignore[union-attr]
    constellation = _constellation(team_id)  # type: ignore[arg-type]
    client, headers = app.test_client(), token_for(people["officer"])  # type: ignore[arg-type]
    url = f"/api/v1/constellations/{constellation.id}"
    response = client.patch(url, json={"team_sudo": True}, headers=headers)
    assert response.status_code == 200, response.get_json()
    assert response.get_json()["team_sudo"] is True
    assert client.get(url, headers=headers).get_json()["team_sudo"] is True
    again = client.patch(url, json={"team_sudo": True}, headers=headers)
    assert again.status_code == 200 and _refreshes(constellation) == 1  # no change, no push
    for bad in ({}, {"team_sudo": "perhaps"}, {"team_sudo": None}):
        response = client.patch(url, json=bad, headers=headers)
        assert response.status_code == 400, (bad, response.status_code)
    assert client.get(url, headers=headers).get_json()["team_sudo"] is True
    assert _refreshes(constellation) == 1
    simple = _constellation(team_id, kind="simple")  # type: ignore[arg-type]
    response = client.patch(
        f"/api/v1/constellations/{simple.id}", json={"team_sudo": True}, headers=headers
    )
    assert response.status_code == 400 and "no field computers" in response.get_json()["message"]
    missing = client.patch(
        "/api/v1/constellations/999999", json={"team_sudo": True}, headers=headers
    )
    assert missing.status_code == 404
