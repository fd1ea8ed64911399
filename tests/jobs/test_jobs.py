"""Jobs run on a real Celery worker against a real Redis, and survive what workers suffer."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from datetime import timedelta
from pathlib import Path

import pytest
from celery.contrib.testing.worker import start_worker
from flask import Flask
from sqlalchemy import select

from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.errors import InvalidInput
from cloudsim.extensions import db
from cloudsim.jobs.service import enqueue, lost_jobs, send, sweep_jobs
from cloudsim.launched_constellations.lifecycle import ConstellationJob
from cloudsim.models import Job, JobState, Team, User, utcnow
from tests.conftest import log_in, running_app
from tests.support import job_kinds
from tests.support.servers import wait_for
from tests.support.workers import job_finished, kill_worker, worker_process


@pytest.fixture
def markers(tmp_path: Path) -> Path:
    """A folder where test.slow jobs leave one file per attempt."""
    path = tmp_path / "markers"
    path.mkdir()
    return path


@pytest.fixture
def worker(app: Flask) -> Iterator[None]:
    with start_worker(
        app.extensions["celery"],
        pool="solo",
        perform_ping_check=False,
        loglevel="WARNING",
        shutdown_timeout=10,
    ):
        yield


def finished(job_id: str, timeout: float = 30) -> Job:
    """Wait for a job to reach a final state and return its row, freshly read."""
    return job_finished(job_id, timeout)


def test_diagnostics_job_runs_on_the_worker(app: Flask, worker: None) -> None:
    job = finished(enqueue("diagnostics", SYSTEM).id)
    assert job.state == JobState.SUCCEEDED, job.error
    assert job.progress == 100 and job.attempts == 1
    for line in ("== database", "job queue reachable", "encryption keys usable", "GiB free"):
        assert line in job.log
    assert job.started_at is not None and job.finished_at >= job.started_at


def test_failed_job_records_the_reason_with_secrets_masked(app: Flask, worker: None) -> None:
    job = finished(enqueue("test.fail", SYSTEM).id)
    assert job.state == JobState.FAILED
    assert job.error == "cloud refused key ***"
    assert job.stage == "talking to the cloud" and job.progress == 40
    assert "Traceback" in job.log and job_kinds.SECRET not in job.log + job.error


def test_a_job_is_sent_only_once_its_transaction_commits(app: Flask, worker: None) -> None:
    dropped = enqueue("diagnostics", SYSTEM).id
    db.session.rollback()  # the caller failed: neither the row nor the message may remain
    assert db.session.get(Job, dropped) is None
    job = enqueue("diagnostics", SYSTEM)
    assert job.state == JobState.QUEUED
    assert finished(job.id).state == JobState.SUCCEEDED  # finished() commits, as a boundary


def test_reports_never_commit_a_failing_job_body_s_changes(app: Flask, worker: None) -> None:
    job = finished(enqueue("test.half_done", SYSTEM, job_kinds.HalfDone("half-done")).id)
    assert job.state == JobState.FAILED and job.error == "failed half-way"
    assert "made a team" in job.log and job.stage == "changing things"
    assert db.session.scalar(select(Team).where(Team.name == "half-done")) is None


def test_a_job_whose_row_is_gone_fails_naming_it(app: Flask, worker: None) -> None:
    job = enqueue("constellation.terminate", SYSTEM, ConstellationJob(4242))
    ended = finished(job.id)
    assert ended.state == JobState.FAILED and ended.error == "constellation 4242 no longer exists"


def test_an_enqueue_with_a_payload_its_kind_does_not_take_is_refused(app: Flask) -> None:
    before = db.session.query(Job).count()
    with pytest.raises(InvalidInput, match="takes a ConstellationJob, not HalfDone"):
        enqueue("constellation.launch", SYSTEM, job_kinds.HalfDone("x"))
    with pytest.raises(InvalidInput, match="takes a ConstellationJob, not NoneType"):
        enqueue("constellation.launch", SYSTEM)
    with pytest.raises(InvalidInput, match="constellation_id must be int"):
        enqueue("constellation.launch", SYSTEM, ConstellationJob("7"))  # type: ignore[arg-type]
    assert db.session.query(Job).count() == before


def test_a_payload_is_stored_on_the_row_and_names_what_the_job_is_about(app: Flask) -> None:
    job = enqueue("constellation.terminate", SYSTEM, ConstellationJob(7))
    assert job.params == {"constellation_id": 7}
    assert (job.target_type, job.target_id) == ("constellation", 7)
    assert ConstellationJob.from_job(job) == ConstellationJob(7)
    # a row queued before payloads existed names its constellation by target only
    job.params = {}
    assert ConstellationJob.from_job(job) == ConstellationJob(7)
    db.session.rollback()


def test_a_second_delivery_of_a_finished_job_does_nothing(app: Flask, worker: None) -> None:
    job = finished(enqueue("diagnostics", SYSTEM).id)
    log_before = job.log
    send(job.id)
    send(job.id)
    sentinel = finished(enqueue("diagnostics", SYSTEM).id)  # the solo worker runs in order
    assert sentinel.state == JobState.SUCCEEDED
    db.session.expire_all()
    again = db.session.get(Job, job.id)
    assert again.attempts == 1 and again.log == log_before


def test_a_job_whose_worker_vanished_is_resumed_by_the_sweeper(
    app: Flask, worker: None, markers: Path
) -> None:
    job = Job(
        id="11111111-2222-3333-4444-555555555555",
        kind="test.slow",
        state=JobState.RUNNING,
        attempts=1,
        heartbeat_at=utcnow() - timedelta(minutes=5),
        params={"marker_dir": str(markers), "steps": 2, "seconds": 0.05},
    )
    db.session.add(job)
    db.session.commit()
    assert [j.id for j in lost_jobs()] == [job.id]
    assert sweep_jobs() == 1
    resumed = finished(job.id)
    assert resumed.state == JobState.SUCCEEDED and resumed.attempts == 2
    assert "resuming after an interrupted attempt (attempt 2)" in resumed.log


def test_a_live_job_is_not_taken_over(app: Flask, worker: None, markers: Path) -> None:
    job = Job(
        id="99999999-2222-3333-4444-555555555555",
        kind="test.slow",
        state=JobState.RUNNING,
        attempts=1,
        heartbeat_at=utcnow(),
        params={"marker_dir": str(markers)},
    )
    db.session.add(job)
    db.session.commit()
    assert lost_jobs() == []
    send(job.id)
    finished(enqueue("diagnostics", SYSTEM).id)
    db.session.expire_all()
    assert db.session.get(Job, job.id).attempts == 1 and not list(markers.iterdir())


def test_a_job_saved_while_the_queue_is_down_is_sent_later(
    make_config: Callable[..., Config],
) -> None:
    dead = make_config(redis_url="redis://127.0.0.1:1/0", stale_job_seconds=0)
    with running_app(dead) as app:
        # each send tries to connect for kombu's connect timeout (Celery's 4 s) before it
        # gives up; refused at once here, so 0.5 s says the same
        app.extensions["celery"].conf.broker_connection_timeout = 0.5
        job = enqueue("diagnostics", SYSTEM)
        db.session.commit()  # the message cannot be sent: the row stays, queued
        assert job.state == JobState.QUEUED
        assert [j.id for j in lost_jobs()] == [job.id]
        assert sweep_jobs() == 0  # still down: nothing sent, nothing lost


def test_job_page_follows_progress_and_log(
    app: Flask, worker: None, people: dict[str, User | None]
) -> None:
    job = finished(enqueue("diagnostics", SYSTEM).id)
    client = app.test_client()
    log_in(client, people["officer"])  # type: ignore[arg-type]
    page = client.get(f"/jobs/{job.id}").get_data(as_text=True)
    assert "succeeded" in page and "encryption keys usable" in page
    full = client.get(f"/jobs/{job.id}/progress").json
    assert full["state"] == "succeeded" and full["progress"] == 100
    tail = client.get(f"/jobs/{job.id}/progress?since={full['log_length'] - 5}").json
    assert tail["log"] == full["log"][-5:]


def test_killing_the_worker_mid_job_loses_nothing(
    make_config: Callable[..., Config], markers: Path, pytestconfig: pytest.Config
) -> None:
    config = make_config(job_lease_seconds=2)
    with running_app(config) as app:
        process = worker_process(config, pytestconfig.rootpath)
        try:
            job = enqueue("test.slow", SYSTEM, job_kinds.Slow(str(markers), steps=6, seconds=0.4))
            db.session.commit()
            wait_for(lambda: (markers / "attempt-1").exists(), 60, "the first attempt")
        finally:
            kill_worker(process)
        db.session.expire_all()
        assert db.session.get(Job, job.id).state == JobState.RUNNING
        wait_for(lambda: lost_jobs(), 10, "the dead worker's lease to expire")
        with start_worker(
            app.extensions["celery"],
            pool="solo",
            perform_ping_check=False,
            loglevel="WARNING",
            shutdown_timeout=10,
        ):
            sweep_jobs()
            done = finished(job.id)
        assert done.state == JobState.SUCCEEDED and done.attempts == 2
        assert (markers / "attempt-2").read_text() == str(os.getpid())
        assert "resuming after an interrupted attempt" in done.log
