"""A team instance's run API says where each run's upload to the master's portal stands, as
the OpenAPI document describes it (a stranger's test: only the documented fields are read)."""

from __future__ import annotations

from datetime import timedelta

from flask import Flask

from cloudsim.extensions import db
from cloudsim.models import PortalUpload, Role, Run, RunState, Team, UploadState, utcnow
from tests.competition.support import open_task
from tests.conftest import make_user, token_for


def _run(task_id: int, team_id: int, state: RunState = RunState.FINISHED) -> Run:
    started = utcnow() - timedelta(minutes=20)
    ended = state in (RunState.FINISHED, RunState.ERROR)
    run = Run(
        task_id=task_id,
        team_id=team_id,
        state=state,
        started_at=started,
        finished_at=started + timedelta(minutes=10) if ended else None,
    )
    db.session.add(run)
    db.session.flush()
    return run


def test_the_run_api_shows_each_runs_upload_as_documented(app: Flask, team_a: Team) -> None:
    spec = app.test_client().get("/api/v1/openapi.json").json
    documented = spec["components"]["schemas"]["RunUpload"]["properties"]
    assert set(documented) == {"state", "percent", "portal_run_id", "error", "next_attempt_at"}
    assert "upload" in spec["components"]["schemas"]["Run"]["properties"]

    keys = iter(range(7, 13))

    def masters() -> int:
        """Add one of the master's tasks (a task has one finished run)."""
        key = next(keys)
        return open_task(team_a.id, name=f"Driving {key}", master_key=f"m{key}").id

    own = open_task(team_a.id, name="Practice").id  # the instance's own task: not uploaded
    retry_at = utcnow() + timedelta(seconds=40)
    runs = {
        "own": _run(own, team_a.id),
        "live": _run(masters(), team_a.id, RunState.RUNNING),
        "not queued yet": _run(masters(), team_a.id),
        "uploading": _run(masters(), team_a.id, RunState.ERROR),
        "uploaded": _run(masters(), team_a.id),
        "refused": _run(masters(), team_a.id),
    }
    db.session.add_all(
        [
            PortalUpload(
                run_id=runs["uploading"].id,
                state=UploadState.UPLOADING,
                bytes_sent=250,
                bytes_total=1000,
                attempts=2,
                next_attempt_at=retry_at,
                error="the master is unreachable (try 2; next in 10 s)",
            ),
            PortalUpload(
                run_id=runs["uploaded"].id,
                state=UploadState.UPLOADED,
                bytes_sent=1000,
                bytes_total=1000,
                master_run_id=412,
                uploaded_at=utcnow(),
            ),
            PortalUpload(
                run_id=runs["refused"].id,
                state=UploadState.REFUSED,
                error="403: task 'm7' was not scheduled for Team A",
            ),
        ]
    )
    db.session.commit()
    ids = {what: run.id for what, run in runs.items()}
    token = token_for(make_user(Role.USER, team_a))
    client = app.test_client()

    def upload(what: str) -> dict[str, object] | None:
        answer = client.get(f"/api/v1/runs/{ids[what]}", headers=token)
        assert answer.status_code == 200
        return answer.json["upload"]  # type: ignore[no-any-return]

    assert upload("own") is None and upload("live") is None
    assert upload("not queued yet") == {
        "state": "pending",
        "percent": 0,
        "portal_run_id": None,
        "error": None,
        "next_attempt_at": None,
    }
    uploading = upload("uploading")
    assert uploading is not None
    assert (uploading["state"], uploading["percent"]) == ("uploading", 25)
    assert "unreachable" in str(uploading["error"])
    assert str(uploading["next_attempt_at"]).startswith(retry_at.strftime("%Y-%m-%dT%H:%M:%S"))
    assert upload("uploaded") == {
        "state": "uploaded",
        "percent": 100,
        "portal_run_id": 412,
        "error": None,
        "next_attempt_at": None,
    }
    refused = upload("refused")
    assert refused is not None and refused["state"] == "refused"
    assert "not scheduled" in str(refused["error"]) and refused["next_attempt_at"] is None
    # the list carries the same
    listed = client.get("/api/v1/runs", headers=token).json
    states = {run["id"]: (run["upload"] or {}).get("state") for run in listed}
    assert states == {
        ids["own"]: None,
        ids["live"]: None,
        ids["not queued yet"]: "pending",
        ids["uploading"]: "uploading",
        ids["uploaded"]: "uploaded",
        ids["refused"]: "refused",
    }
