"""A run whose end cannot be established waits in `needs_review`; an officer settles it on its
page (audited); failures carry their codes."""

from __future__ import annotations

import uuid

from flask import Flask
from sqlalchemy import select

from cloudsim.competition.supervision import MAX_STOP_ATTEMPTS, _retry_failed_stops
from cloudsim.extensions import db
from cloudsim.models import AuditEvent, Job, JobState, Run, RunState, User
from tests.competition.support import open_task
from tests.conftest import csrf_token, log_in


def _stuck_run(user: User) -> Run:
    """Add a run left `stopping` by stop jobs that failed every time."""
    assert user.team_id is not None
    task = open_task(user.team_id)
    run = Run(task_id=task.id, team_id=task.team_id, state=RunState.STOPPING, stop_reason="timeout")
    db.session.add(run)
    db.session.flush()
    for attempt in range(MAX_STOP_ATTEMPTS):
        db.session.add(
            Job(
                id=str(uuid.uuid4()),
                kind="run.stop",
                target_type="run",
                target_id=run.id,
                state=JobState.FAILED,
                error=f"sim unreachable (try {attempt + 1})",
            )
        )
    db.session.commit()
    return run


def test_a_run_whose_stop_keeps_failing_goes_to_review_and_an_officer_settles_it(
    app: Flask, people: dict[str, User | None]
) -> None:
    user, officer = people["user_a"], people["officer"]
    assert user is not None and officer is not None
    run = _stuck_run(user)
    _retry_failed_stops()
    db.session.commit()
    assert run.state == RunState.NEEDS_REVIEW and run.error_code == "RUN-END-UNKNOWN"
    assert "stop failed 3 times" in (run.error or "") and run.review_since is not None

    member = app.test_client()
    log_in(member, user)
    status = member.get(f"/runs/{run.id}/status").json
    assert (status["state"], status["error_code"]) == ("needs_review", "RUN-END-UNKNOWN")
    page = member.get(f"/runs/{run.id}").get_data(as_text=True)
    assert "RUN-END-UNKNOWN" in page and "Settle this run" not in page
    forged = {"decision": "accept", "note": "mine", "csrf_token": csrf_token(page)}
    assert member.post(f"/runs/{run.id}/settle", data=forged).status_code == 403

    client = app.test_client()
    log_in(client, officer)
    page = client.get(f"/runs/{run.id}").get_data(as_text=True)
    assert "Settle this run" in page
    token = csrf_token(page.split('id="settle"', 1)[1])
    empty = client.post(
        f"/runs/{run.id}/settle", data={"decision": "fail", "note": " ", "csrf_token": token}
    )
    assert empty.status_code == 400
    db.session.expire_all()
    assert db.session.get(Run, run.id).state == RunState.NEEDS_REVIEW  # type: ignore[union-attr]

    settled = client.post(
        f"/runs/{run.id}/settle",
        data={"decision": "fail", "note": "sim never came back", "csrf_token": token},
    )
    assert settled.status_code == 302
    db.session.expire_all()
    done = db.session.get(Run, run.id)
    assert done is not None and done.state == RunState.ERROR
    assert done.error_code == "RUN-REVIEWED-FAILED" and done.officer_note == "sim never came back"
    event = db.session.scalars(select(AuditEvent).where(AuditEvent.action == "run.review")).one()
    assert event.details["decision"] == "fail" and event.target_id == str(run.id)
    again = client.post(
        f"/runs/{run.id}/settle",
        data={"decision": "accept", "note": "changed my mind", "csrf_token": token},
    )
    assert again.status_code == 409  # only a run in review is settled
