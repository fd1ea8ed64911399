"""Verification re-simulates real drcsim runs from their own logs on real Celery workers: an
untouched run verifies, one edited command holds its run for review, held runs are not ranked
until an officer accepts them."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from celery.contrib.testing.worker import start_worker
from drcsim.worlds import shipped_document
from flask import Flask
from sqlalchemy import select

from cloudsim.auth.policy import SYSTEM
from cloudsim.competition.runs import leaderboard
from cloudsim.extensions import db
from cloudsim.models import AuditEvent, Job, JobState, Role, Run, Verification
from cloudsim.people.service import create_team
from cloudsim.verification import service
from tests.competition.support import open_task
from tests.conftest import log_in, make_user, token_for
from tests.support.workers import job_finished
from tests.verification.support import TIMEOUT_S, WORLD_NAME, edit_command, master_run, simulate

REPLAY_WAIT_S = 600  # two replays of 2.5 simulated seconds, on a machine shared by many


@pytest.fixture(scope="module")
def real_logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    """The logs of one real short run of the world as drcsim ships it (as CloudSim holds it)."""
    return simulate(tmp_path_factory.mktemp("run"), shipped_document(WORLD_NAME))


@pytest.fixture
def workers(app: Flask) -> Iterator[None]:
    """A real Celery worker taking two jobs at once."""
    with start_worker(
        app.extensions["celery"],
        pool="threads",
        concurrency=2,
        perform_ping_check=False,
        loglevel="WARNING",
        shutdown_timeout=30,
    ):
        yield


def _verified(run_ids: list[int]) -> dict[int, Run]:
    jobs = list(db.session.scalars(select(Job).where(Job.kind == service.VERIFY)))
    assert sorted(job.target_id for job in jobs if job.target_id) == sorted(run_ids)
    for job in jobs:
        done = job_finished(job.id, REPLAY_WAIT_S)
        assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log}"
    db.session.expire_all()
    return {run_id: db.session.get(Run, run_id) for run_id in run_ids}  # type: ignore[misc]


def test_an_untouched_run_verifies_and_an_edited_command_holds_its_run(
    app: Flask, workers: None, real_logs: dict[str, bytes], tmp_path: Path
) -> None:
    team_a, team_b = create_team(SYSTEM, "Team A"), create_team(SYSTEM, "Team B")
    honest = master_run(open_task(team_a.id, timeout_s=TIMEOUT_S), real_logs, tmp_path)
    edited = master_run(
        open_task(team_b.id, timeout_s=TIMEOUT_S), edit_command(real_logs), tmp_path
    )
    assert honest.sim_seconds == edited.sim_seconds == 2.5  # the score logs say the same
    assert service.sweep() == 2 and service.sweep() == 0  # queued once each
    db.session.commit()
    runs = _verified([honest.id, edited.id])

    assert runs[honest.id].verification == Verification.VERIFIED
    assert runs[honest.id].verification_reason is None
    held = runs[edited.id]
    assert held.verification == Verification.HELD
    assert "the replay of its command log diverged: state differs at step" in (
        held.verification_reason or ""
    )
    # a held run is not ranked; the board says so
    standings = {s.team: s for s in leaderboard(SYSTEM)}
    assert (standings["Team A"].runs, standings["Team A"].held) == (1, 0)
    assert (standings["Team B"].runs, standings["Team B"].held) == (0, 1)

    # what the API and the run page show
    officer = make_user(Role.OFFICER)
    headers = token_for(officer)
    client = app.test_client()
    shown = client.get(f"/api/v1/runs/{edited.id}", headers=headers).json
    assert shown["verification"] == "held" and "state differs" in shown["verification_reason"]
    assert client.get(f"/api/v1/runs/{honest.id}", headers=headers).json["verification"] == (
        "verified"
    )
    log_in(client, officer)
    page = client.get(f"/runs/{edited.id}").get_data(as_text=True)
    assert "held for review" in page and "state differs at step" in page

    # an officer accepts it (audited): it is ranked again
    accepted = client.patch(
        f"/api/v1/runs/{edited.id}/review",
        json={"accepted": True, "reason": "the edit was our replay's test"},
        headers=headers,
    )
    assert accepted.status_code == 200, accepted.json
    assert accepted.json["verification"] == "accepted"
    again = client.patch(
        f"/api/v1/runs/{honest.id}/review", json={"accepted": True}, headers=headers
    )
    assert again.status_code == 409 and "not held for review" in again.json["message"]
    standings = {s.team: s for s in leaderboard(SYSTEM)}
    assert (standings["Team B"].runs, standings["Team B"].held) == (1, 0)
    audit = db.session.scalar(select(AuditEvent).where(AuditEvent.action == "run.accept"))
    assert audit is not None and audit.target_id == str(edited.id)
    outcomes = db.session.scalars(select(AuditEvent).where(AuditEvent.action == "run.verify"))
    assert sorted(event.details["outcome"] for event in outcomes) == ["held", "verified"]
