"""What current-run.json tells team code, and that a spent cap's time reaches the run."""

from __future__ import annotations

import json
from datetime import timedelta

from csrouter.bandwidth_log import read_bandwidth_log
from flask import Flask

from cloudsim.competition.current_run import current_run_document
from cloudsim.extensions import db
from cloudsim.models import Run, RunState, Team, utcnow
from tests.competition.support import open_task
from tests.conftest import log_in, token_for


def test_the_document_names_the_run_world_config_end_and_simulator(
    app: Flask, team_a: Team
) -> None:
    task = open_task(team_a.id, world="vrc_task_1", run_config=3, timeout_s=600)
    started = utcnow()
    run = Run(task_id=task.id, team_id=team_a.id, state=RunState.RUNNING, running_at=started)
    db.session.add(run)
    db.session.commit()
    document = json.loads(json.dumps(current_run_document(run, "10.0.0.51")))
    assert document["run_id"] == run.id and document["world"] == "vrc_task_1"
    assert document["config"] == 3 and document["time_limit_s"] == 600
    assert document["ends_at"] == (started + timedelta(seconds=600)).isoformat()
    assert document["simulator"] == {"host": "10.0.0.51", "command_port": 7700}


def test_a_spent_cap_shows_with_its_time_on_the_status_and_the_api(
    app: Flask, people: dict[str, object]
) -> None:
    user = people["user_a"]
    task = open_task(user.team_id)  # type: ignore[attr-defined]
    spent = utcnow() - timedelta(seconds=30)
    run = Run(
        task_id=task.id,
        team_id=task.team_id,
        state=RunState.RUNNING,
        uplink_bits_used=task.uplink_bits,
        uplink_spent_at=spent,
    )
    db.session.add(run)
    db.session.commit()
    answer = app.test_client().get(f"/api/v1/runs/{run.id}", headers=token_for(user))  # type: ignore[arg-type]
    assert answer.get_json()["uplink_spent_at"].startswith(spent.isoformat()[:19])
    assert answer.get_json()["downlink_spent_at"] is None
    client = app.test_client()
    log_in(client, user)  # type: ignore[arg-type]
    status = client.get(f"/runs/{run.id}/status").get_json()
    assert status["spent_since"]["uplink"] and status["spent_since"]["downlink"] is None
    page = client.get(f"/runs/{run.id}").get_data(as_text=True)
    # the page and its live updates show one text, with the time as the page writes times
    shown = f"uplink spent since {spent:%Y-%m-%d %H:%M:%S} UTC (traffic that way is dropped)"
    assert status["caps_spent"] == shown and f'class="error">{shown}</dd>' in page
    final = {"uplink": {"spent_at": "2026-11-22T20:00:01.000+00:00"}, "downlink": {}}
    usage = read_bandwidth_log(
        [json.dumps({"time": "2026-11-22T20:00:02+00:00", "event": "disarmed", "counters": final})]
    )
    assert usage["uplink"].spent_at is not None and usage["downlink"].spent_at is None
