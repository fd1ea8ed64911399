"""Terminate during a launch: the launch stops at its next step, nothing leaks, and the
constellation stays terminated."""

from __future__ import annotations

import pytest
from flask import Flask

from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.jobs.runner import HELD
from cloudsim.launched_constellations import service
from cloudsim.models import Constellation, ConstellationState, Job, JobState, MachineState, Role
from cloudsim.providers.service import open_provider
from tests.conftest import make_user, token_for
from tests.launched_constellations.conftest import finished, leftovers
from tests.support.servers import wait_for

pytestmark = pytest.mark.hosts


def test_terminate_during_a_launch_stops_it_and_the_constellation_stays_terminated(
    constellations_app: Flask, constellations_config: Config, constellations_worker: None
) -> None:
    headers = token_for(make_user(Role.ADMIN))
    client = constellations_app.test_client()
    constellation, launch = service.launch(SYSTEM, name="cancelled", kind="vrc", provider="local")
    db.session.commit()  # the test is the boundary: its commit sends the launch job
    provider = open_provider("local", constellations_config)
    # a few seconds in: the first machine exists, the others are being made
    wait_for(lambda: provider.nodes(constellation.name), 300, "a first machine")
    response = client.delete(f"/api/v1/constellations/{constellation.id}", headers=headers)
    assert response.status_code == 202, response.get_data(as_text=True)
    terminate_id = response.get_json()["id"]
    answers: list[int] = []

    def launch_ended() -> bool:
        # the site answers while the launch stops and the terminate releases
        answers.append(client.get("/api/v1/constellations", headers=headers).status_code)
        db.session.expire_all()
        return db.session.get(Job, launch.id).state.final  # type: ignore[union-attr]

    wait_for(launch_ended, 60, "the launch to stop")
    stopped = db.session.get(Job, launch.id)
    assert stopped is not None and stopped.state == JobState.FAILED
    assert "cancelled: cancelled is being terminated" in (stopped.error or ""), stopped.log[-2000:]
    assert HELD not in stopped.log
    terminate = finished(terminate_id, 300)
    assert terminate.state == JobState.SUCCEEDED, f"{terminate.error}\n{terminate.log[-2000:]}"
    # the terminate waited for the launch, then released what it had made
    assert stopped.finished_at is not None and terminate.finished_at is not None
    assert stopped.finished_at <= terminate.finished_at
    assert "still running" not in terminate.log
    assert set(answers) == {200}
    db.session.expire_all()
    row = db.session.get(Constellation, constellation.id)
    assert row is not None and row.state == ConstellationState.TERMINATED and row.error is None
    assert {m.state for m in row.machines} == {MachineState.TERMINATED}
    assert provider.nodes(constellation.name) == []
    assert leftovers(constellations_config) == {"netns": [], "mounts": [], "files": []}
    page = client.get(f"/api/v1/constellations/{constellation.id}", headers=headers).get_json()
    assert page["state"] == "terminated"
