"""The team-sudo toggle as a stranger uses it: the page's button really submitted, the API
called with the documented body; each change audited and pushed, also one made while the
constellation was still launching (that one on local hosts)."""

from __future__ import annotations

import re

import pytest
from flask import Flask
from flask.testing import FlaskClient
from sqlalchemy import func, select

from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations import service
from cloudsim.launched_constellations.connect import machine_host_keys, targets
from cloudsim.launched_constellations.keys import constellation_keypair
from cloudsim.models import AuditEvent, Constellation, Job, JobState, User
from cloudsim.people.service import create_team
from constellations.plans.roles import TEAM_SUDOERS
from provisioners.remote.ssh import SSHExecutor
from tests.competition.support import ready_constellation
from tests.conftest import csrf_token, log_in, token_for
from tests.launched_constellations.conftest import finished
from tests.support.servers import wait_for


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
    return _count(
        Job, Job.kind == "constellation.refresh_access", Job.target_id == constellation.id
    )


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


@pytest.mark.hosts
def test_sudo_allowed_while_launching_reaches_the_field_computers_once_ready(
    constellations_app: Flask, constellations_worker: None, constellations_config: Config
) -> None:
    team = create_team(SYSTEM, "Late sudoers")
    constellation, job = service.launch(
        SYSTEM, name="sudolate", kind="vrc", provider="local", team_id=team.id
    )
    db.session.commit()  # the test is the boundary: its commit sends the launch job

    def verifying() -> bool:
        db.session.expire_all()
        return db.session.get(Job, job.id).stage == "verify"  # type: ignore[union-attr]

    wait_for(verifying, 600, "the verify stage (the field computers are installed)")
    service.set_team_sudo(SYSTEM, constellation.id, True)
    db.session.commit()
    assert _refreshes(constellation) == 0  # still launching: nothing pushes it now
    done = finished(job.id)
    assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log[-3000:]}"
    assert "changed during the launch" in done.log
    refresh = db.session.scalar(
        select(Job).where(
            Job.kind == "constellation.refresh_access", Job.target_id == constellation.id
        )
    )
    assert refresh is not None and finished(refresh.id).state == JobState.SUCCEEDED
    db.session.refresh(constellation)
    keys = constellation_keypair(constellation)
    reach = targets(constellation, keys, constellations_config)
    with SSHExecutor(machine_host_keys(constellation), secrets=[keys.private]) as executor:
        sudoers = executor.run(reach["fc1"], f"cat {TEAM_SUDOERS}", check=False)
    assert sudoers.ok and "NOPASSWD" in sudoers.stdout, sudoers.stderr
