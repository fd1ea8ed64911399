"""A launch never goes silent: its page says the current step and since when, each machine's
last-heard time, and a failure's code; so does the API."""

from __future__ import annotations

import uuid
from datetime import UTC, datetime

from flask import Flask

from cloudsim.competition import live
from cloudsim.extensions import db
from cloudsim.models import Constellation, ConstellationState, Job, JobState, Machine, User
from tests.conftest import log_in, token_for


def test_the_launch_page_says_the_step_since_when_and_when_each_machine_was_heard(
    app: Flask, people: dict[str, User | None]
) -> None:
    officer, member = people["officer"], people["user_a"]
    assert officer is not None and member is not None
    constellation = Constellation(
        name="heard",
        kind="vrc",
        provider="local",
        team_id=member.team_id,
        state=ConstellationState.ERROR,
        error="verify: verification failed: sim: the simulator ran at a real-time factor of 0.5",
        error_code="LAUNCH-SIM-SLOW",
    )
    db.session.add(constellation)
    db.session.flush()
    db.session.add_all(
        [
            Machine(constellation_id=constellation.id, name="sim", role="sim"),
            Machine(
                constellation_id=constellation.id,
                name="router",
                role="router",
                verification={"checks": [], "at": "2026-11-27T21:00:09+00:00"},
            ),
        ]
    )
    job = Job(
        id=str(uuid.uuid4()),
        kind="constellation.launch",
        target_type="constellation",
        target_id=constellation.id,
        state=JobState.FAILED,
        stage="verify",
        log="21:00:01 == machines\n21:00:02 created sim\n21:00:07 == verify\n21:00:30 failed\n",
    )
    db.session.add(job)
    db.session.commit()
    job.updated_at = datetime(2026, 11, 27, 21, 0, 30, tzinfo=UTC)
    db.session.commit()
    config = app.config["CLOUDSIM"]
    live.connection(config).hset(
        live.HEARD_KEY.format(constellation.id), "sim", "2026-11-27T21:00:29+00:00"
    )

    for user in (officer, member):
        client = app.test_client()
        log_in(client, user)
        status = client.get(f"/constellations/{constellation.id}/status").json
        assert status["step"] == "verify"
        assert status["step_since"] == "2026-11-27T21:00:07+00:00"
        assert status["error_code"] == "LAUNCH-SIM-SLOW"
        heard = {m["name"]: m["heard"] for m in status["machines"]}
        assert heard == {
            "sim": "2026-11-27T21:00:29+00:00",
            "router": "2026-11-27T21:00:09+00:00 (verification)",
        }
        page = client.get(f"/constellations/{constellation.id}").get_data(as_text=True)
        assert "LAUNCH-SIM-SLOW" in page and "2026-11-27T21:00:07+00:00" in page
        assert "2026-11-27T21:00:29+00:00" in page
        # the API answers the same, from the same helpers
        answer = app.test_client().get(
            f"/api/v1/constellations/{constellation.id}", headers=token_for(user)
        )
        assert answer.status_code == 200, answer.get_json()
        found = answer.get_json()
        assert (found["step"], found["step_since"]) == ("verify", "2026-11-27T21:00:07+00:00")
        assert (found["job_kind"], found["job_state"]) == ("constellation.launch", "failed")
        assert (found["state"], found["error_code"]) == ("error", "LAUNCH-SIM-SLOW")
        assert {m["name"]: m["heard"] for m in found["machines"]} == heard
    stranger = people["user_b"]
    assert stranger is not None
    hidden = app.test_client().get(
        f"/api/v1/constellations/{constellation.id}", headers=token_for(stranger)
    )
    assert hidden.status_code == 404
