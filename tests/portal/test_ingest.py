"""Uploads from a team instance to its master's portal over pinned HTTPS: a real master web
server, the instance's outbox sent by a real worker, resumed after the portal was killed
mid-log, refusals recorded, duplicates ignored, invalidated runs out of the ranking."""

from __future__ import annotations

import hashlib
import os
import threading
from collections.abc import Callable, Iterator
from dataclasses import replace
from datetime import timedelta
from pathlib import Path

import pytest
import redis
from flask import Flask
from sqlalchemy import func, select

from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations.keys import deployment_ca
from cloudsim.models import (
    Artifact,
    PortalRefusal,
    PortalUpload,
    Role,
    Run,
    Task,
    UploadState,
    utcnow,
)
from cloudsim.portal import outbox
from cloudsim.portal.credentials import portal_endpoint
from cloudsim.team_instances.client import call
from cloudsim.team_instances.health import HEARTBEAT_KEY
from provisioners.remote import pki
from tests.conftest import csrf_token, log_in, make_user, running_app, token_for
from tests.portal.ingest_support import Portal, finished_run, start_master, sync_instance
from tests.support.servers import free_port, wait_for
from tests.support.workers import kill_worker, worker_process


@pytest.fixture
def portal(
    make_config: Callable[..., Config], tmp_path: Path, request: pytest.FixtureRequest
) -> Iterator[Portal]:
    port = free_port()
    config = make_config(instance_dir=tmp_path / "master", portal_url=f"https://127.0.0.1:{port}/")
    made = start_master(config, request.config.rootpath)
    try:
        yield made
    finally:
        made.server.kill()
        with made.master.app_context():
            db.engine.dispose()


@pytest.fixture
def instance(make_config: Callable[..., Config], tmp_path: Path) -> Iterator[Flask]:
    config = make_config(instance_dir=tmp_path / "instance", portal_retry_seconds=1)
    with running_app(config) as app:
        yield app


def _master_run(portal: Portal, remote_id: int) -> Run | None:
    with portal.on_master():
        run = db.session.scalar(select(Run).where(Run.remote_run_id == remote_id))
        if run is not None:
            db.session.expunge(run)
        return run


def test_a_finished_run_reaches_the_master_through_a_real_worker(
    portal: Portal, instance: Flask, tmp_path: Path, request: pytest.FixtureRequest
) -> None:
    client = instance.test_client()
    sync_instance(portal, client)
    # the state log takes two pieces: a full 8 MiB one (over the API's 2 MB bound) and the rest
    logs = {"score.jsonl": b'{"checkpoint": 1}\n' * 1000, "state.msgpack": os.urandom(9 << 20)}
    run = finished_run("Driving 1", logs, tmp_path)
    worker = worker_process(instance.config["CLOUDSIM"], request.config.rootpath)
    try:
        instance.extensions["celery"].send_task(outbox.TASK)  # what the beat sends

        def uploaded() -> bool:
            db.session.rollback()
            row = db.session.scalar(select(PortalUpload).where(PortalUpload.run_id == run.id))
            return row is not None and row.state == UploadState.UPLOADED

        wait_for(uploaded, 60, "the upload acknowledged")
    finally:
        kill_worker(worker)
    # the master's own run: marked with the instance, score events and logs with checksums
    with portal.on_master():
        got = db.session.scalar(select(Run).where(Run.remote_run_id == run.id))
        assert got is not None and got.instance_id == portal.instance_id
        assert (got.score, got.falls, got.end_reason, got.task_id) == (
            2,
            1,
            "time_limit",
            portal.task_ids["Driving 1"],
        )
        assert [e.checkpoint for e in got.score_events] == [1, 2]
        assert got.logs_complete_at is not None
        master_run_id = got.id
    shown = portal.master_client().get(f"/api/v1/runs/{master_run_id}", headers=portal.user_token)
    assert shown.status_code == 200 and shown.json["instance_id"] == portal.instance_id
    for artifact in shown.json["artifacts"]:
        body = portal.master_client().get(
            f"/api/v1/runs/{master_run_id}/logs/{artifact['id']}", headers=portal.officer_token
        )
        assert hashlib.sha256(body.data).hexdigest() == artifact["sha256"]
        assert body.data == logs.get(artifact["filename"], b"")  # the rest declared empty
    browser = portal.master_client()
    with portal.on_master():
        log_in(browser, make_user(Role.OFFICER))
    shown_page = browser.get(f"/runs/{master_run_id}").get_data(as_text=True)
    assert f"ti-a (its run {run.id})" in shown_page and "all received and checked" in shown_page
    # the instance's run page says so
    log_in(client, make_user(Role.OFFICER))
    page = client.get(f"/runs/{run.id}").get_data(as_text=True)
    assert "uploaded" in page and f"run {master_run_id} on the master" in page
    member = token_for(make_user(Role.USER, run.team))
    upload = client.get(f"/api/v1/runs/{run.id}", headers=member).json
    assert (upload["upload"]["state"], upload["upload"]["portal_run_id"]) == (
        "uploaded",
        master_run_id,
    )
    # sending the same run again adds nothing
    endpoint = portal_endpoint()
    assert endpoint is not None
    again = call(endpoint, "PUT", f"/portal/ingest/runs/{run.id}", outbox.run_record(run))
    assert again["run_id"] == master_run_id and again["complete"] is True
    with portal.on_master():
        assert db.session.scalar(select(func.count(Run.id))) == 1


def test_an_upload_cut_off_by_the_portal_resumes_after_it_restarts(
    portal: Portal, instance: Flask, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    sync_instance(portal, instance.test_client())
    monkeypatch.setattr(outbox, "PIECE", 256 * 1024)  # many pieces: the kill lands mid-log
    content = os.urandom(12 * 1024 * 1024)
    run = finished_run("Driving 1", {"state.msgpack": content}, tmp_path)
    config: Config = instance.config["CLOUDSIM"]
    staged = portal.server.config.instance_dir / "portal" / "staging"

    def send() -> None:
        with instance.app_context():
            outbox.upload_outbox(config)

    sender = threading.Thread(target=send)
    sender.start()
    parts = lambda: [p for p in staged.rglob("*.part") if p.stat().st_size >= 1024 * 1024]  # noqa: E731
    wait_for(parts, 60, "a megabyte of the log on the master")
    portal.server.kill()  # the portal goes down halfway through the log
    sender.join(60)
    db.session.rollback()
    row = db.session.scalar(select(PortalUpload).where(PortalUpload.run_id == run.id))
    assert row is not None and row.state == UploadState.UPLOADING and row.error, row
    assert 0 < row.bytes_sent < len(content)
    portal.server.start()
    endpoint = portal_endpoint()
    assert endpoint is not None
    kept = call(endpoint, "GET", f"/portal/ingest/runs/{run.id}/logs/state.msgpack")
    assert 0 < kept["received"] < len(content) and not kept["complete"]  # resumes from here
    row.next_attempt_at = utcnow()
    db.session.commit()
    assert outbox.upload_outbox(config) == 1
    db.session.refresh(row)
    assert row.state == UploadState.UPLOADED and row.bytes_sent == len(content)
    with portal.on_master():
        artifact = db.session.scalar(select(Artifact).where(Artifact.filename == "state.msgpack"))
        assert artifact is not None
        # the state log's own (a finished run also declares other, empty logs)
        sent = next(a for a in run.artifacts if a.filename == "state.msgpack")
        assert artifact.sha256 == hashlib.sha256(content).hexdigest() == sent.sha256


def test_the_outbox_catches_up_within_10_s_of_the_master_answering_again(
    portal: Portal, instance: Flask, tmp_path: Path, request: pytest.FixtureRequest
) -> None:
    sync_instance(portal, instance.test_client())
    run = finished_run("Driving 1", {"score.jsonl": b'{"checkpoint": 1}\n' * 10}, tmp_path)
    config: Config = instance.config["CLOUDSIM"]
    portal.server.kill()  # an outage of the master
    assert outbox.upload_outbox(config) == 0
    row = db.session.scalar(select(PortalUpload).where(PortalUpload.run_id == run.id))
    assert row is not None and "unreachable" in (row.error or ""), row
    # a long outage: the wait has doubled up to the report's 160 s
    row.attempts, row.next_attempt_at = 6, utcnow() + timedelta(seconds=160)
    db.session.commit()
    worker = worker_process(
        config, request.config.rootpath, beat_schedule=tmp_path / "beat-schedule"
    )
    try:
        # the worker and its beat are up once the beat's first heartbeat was taken
        beats = redis.Redis.from_url(config.effective_redis_url)
        wait_for(lambda: beats.exists(HEARTBEAT_KEY), 60, "the instance's worker and beat")
        portal.server.start()
        endpoint = portal_endpoint()
        assert endpoint is not None
        # the clock starts when the master answers (its port opens before its app is loaded)
        wait_for(lambda: outbox.master_answers(endpoint), 60, "the master answering again")

        def uploaded() -> bool:
            db.session.rollback()
            db.session.refresh(row)
            return row.state == UploadState.UPLOADED

        wait_for(uploaded, 10, "the run on the portal within 10 s of the master answering")
    finally:
        kill_worker(worker)
    assert _master_run(portal, run.id) is not None


def test_results_the_instance_may_not_send_are_refused_and_shown_to_officers(
    portal: Portal, instance: Flask, tmp_path: Path
) -> None:
    sync_instance(portal, instance.test_client())
    run = finished_run("Driving 1", {"score.jsonl": b"{}\n"}, tmp_path)
    record = outbox.run_record(run)
    master = portal.master_client()
    token = {"Authorization": f"Bearer {portal.upload_token()}"}
    url = f"/api/v1/portal/ingest/runs/{run.id}"
    with portal.on_master():
        theirs = db.session.get(Task, portal.task_ids["Theirs"])
        assert theirs is not None
        their_key = f"m{theirs.id}"
    refused = {
        "another team's result": dict(record, team="Team B"),
        "a task not scheduled for the team": dict(record, task_key=their_key),
        "a run that ended after its window": dict(
            record, finished_at=(utcnow() + timedelta(days=1)).isoformat()
        ),
    }
    for what, body in refused.items():
        answer = master.put(url, json=body, headers=token)
        assert answer.status_code == 403, (what, answer.json)
    assert (
        master.put(url, json=record, headers={"Authorization": "Bearer cspu_1_x"}).status_code
        == 401
    )
    assert master.put(url, json={"team": 1}, headers=token).status_code == 400
    assert _master_run(portal, run.id) is None  # nothing was taken
    listed = master.get("/api/v1/portal/refusals", headers=portal.officer_token)
    assert listed.status_code == 200 and len(listed.json) == 3
    reasons = " | ".join(r["reason"] for r in listed.json)
    assert "serves 'Team A' only" in reasons and "not scheduled for Team A" in reasons
    assert "outside its task's window" in reasons
    assert master.get("/api/v1/portal/refusals", headers=portal.user_token).status_code == 403
    page_client = portal.master_client()
    with portal.on_master():
        log_in(page_client, make_user(Role.OFFICER))
    page = page_client.get("/portal/refusals").get_data(as_text=True)
    assert "serves &#39;Team A&#39; only" in page and "outside its task" in page
    assert page_client.get("/portal/refusals?page=99999999999").status_code == 200  # past the end
    # the accepted record, twice: one run
    first = master.put(url, json=record, headers=token)
    second = master.put(url, json=record, headers=token)
    assert first.status_code == second.status_code == 200
    assert first.json["run_id"] == second.json["run_id"]
    # a log with the wrong bytes: refused for its checksum, recorded, nothing stored
    wrong = master.put(
        f"{url}/logs/score.jsonl?offset=0",
        data=b"{!\n",
        headers=token,
        content_type="application/octet-stream",
    )
    assert wrong.status_code == 422 and "checksum" in wrong.json["message"]
    out_of_place = master.put(
        f"{url}/logs/score.jsonl?offset=7",
        data=b"x",
        headers=token,
        content_type="application/octet-stream",
    )
    assert out_of_place.status_code == 409 and out_of_place.json["received"] == 0
    with portal.on_master():
        assert db.session.scalar(select(func.count(PortalRefusal.id))) == 4
        stored = select(func.count(Artifact.id)).where(Artifact.filename == "score.jsonl")
        assert db.session.scalar(stored) == 0  # (the empty logs it declared are stored at once)


def test_an_invalidated_run_leaves_the_ranking_and_the_leaderboard_says_so(
    portal: Portal, instance: Flask, tmp_path: Path
) -> None:
    sync_instance(portal, instance.test_client())
    run = finished_run("Driving 1", {}, tmp_path, score=3)
    master = portal.master_client()
    token = {"Authorization": f"Bearer {portal.upload_token()}"}
    got = master.put(
        f"/api/v1/portal/ingest/runs/{run.id}", json=outbox.run_record(run), headers=token
    )
    assert got.status_code == 200 and got.json["complete"]
    run_id = got.json["run_id"]
    board = master.get("/api/v1/leaderboard", headers=portal.officer_token).json
    assert (board[0]["team"], board[0]["checkpoints"], board[0]["invalidated"]) == ("Team A", 3, 0)
    review = f"/api/v1/runs/{run_id}/review"
    assert (
        master.patch(review, json={"invalidated": True}, headers=portal.officer_token).status_code
        == 400
    )
    assert (
        master.patch(
            review, json={"invalidated": True, "reason": "x"}, headers=portal.user_token
        ).status_code
        == 403
    )
    done = master.patch(
        review,
        json={"invalidated": True, "reason": "ran twice", "note": "see log"},
        headers=portal.officer_token,
    )
    assert done.status_code == 200 and done.json["invalid_reason"] == "ran twice"
    board = {
        s["team"]: s for s in master.get("/api/v1/leaderboard", headers=portal.officer_token).json
    }
    assert (
        board["Team A"]["checkpoints"],
        board["Team A"]["runs"],
        board["Team A"]["invalidated"],
    ) == (0, 0, 1)
    audit = master.get("/api/v1/audit?action=run.invalidate", headers=portal.officer_token)
    assert [e["details"]["reason"] for e in audit.json] == ["ran twice"]
    # the run page's review form, as an officer submits it: counted again, with a note
    browser = portal.master_client()
    with portal.on_master():
        log_in(browser, make_user(Role.OFFICER))
    page = browser.get(f"/runs/{run_id}").get_data(as_text=True)
    assert "ran twice" in page and "Review this run" in page
    saved = browser.post(
        f"/runs/{run_id}/review",
        data={"csrf_token": csrf_token(page), "note": "checked again", "reason": ""},
        follow_redirects=True,
    )
    assert saved.status_code == 200 and "Review saved." in saved.get_data(as_text=True)
    board = {
        s["team"]: s for s in master.get("/api/v1/leaderboard", headers=portal.officer_token).json
    }
    assert (board["Team A"]["checkpoints"], board["Team A"]["invalidated"]) == (3, 0)
    with portal.on_master():
        reviewed = db.session.get(Run, run_id)
        assert reviewed is not None and reviewed.officer_note == "checked again"


def test_an_instance_sends_nothing_to_a_portal_with_another_certificate(
    portal: Portal, instance: Flask, tmp_path: Path
) -> None:
    sync_instance(portal, instance.test_client())
    run = finished_run("Driving 1", {"score.jsonl": b"{}\n"}, tmp_path)
    portal.server.kill()
    with portal.on_master():  # the same CA and address, not the pinned certificate
        impostor = pki.issue_tls_server(deployment_ca(), "impostor", ["127.0.0.1"])
    folder = portal.server.config.instance_dir / "tls"
    (folder / "portal.crt").write_text(impostor.cert_pem)
    (folder / "portal.key").write_text(impostor.key_pem)
    portal.server.start()
    assert outbox.upload_outbox(instance.config["CLOUDSIM"]) == 0
    row = db.session.scalar(select(PortalUpload).where(PortalUpload.run_id == run.id))
    assert row is not None and row.state == UploadState.PENDING
    assert row.error and "does not match the pinned one" in row.error
    officer = token_for(make_user(Role.OFFICER))
    shown = instance.test_client().get(f"/api/v1/runs/{run.id}", headers=officer).json["upload"]
    assert shown["state"] == "pending" and "does not match the pinned one" in shown["error"]
    assert shown["next_attempt_at"] and shown["portal_run_id"] is None
    assert _master_run(portal, run.id) is None


def test_two_instances_runs_are_ranked_together_a_tie_broken_by_bits(
    portal: Portal, instance: Flask, make_config: Callable[..., Config], tmp_path: Path
) -> None:
    sync_instance(portal, instance.test_client())
    run_a = finished_run("Driving 1", {}, tmp_path, uplink_bits_used=600_000).id
    assert outbox.upload_outbox(instance.config["CLOUDSIM"]) == 1
    config_b = replace(
        instance.config["CLOUDSIM"],
        instance_dir=tmp_path / "instance-b",
        database_url=f"sqlite:///{tmp_path / 'instance-b.db'}",
    )
    (tmp_path / "instance-b").mkdir(mode=0o700)
    with running_app(config_b) as team_b_instance:
        sync_instance(portal, team_b_instance.test_client(), portal.other_instance_id)
        run_b = finished_run("Theirs", {}, tmp_path / "b", uplink_bits_used=300_000).id
        assert outbox.upload_outbox(config_b) == 1
    board = portal.master_client().get("/api/v1/leaderboard", headers=portal.officer_token).json
    # two checkpoints each; Team B left more of its uplink cap (1,000,000 bits) unused
    assert [(s["rank"], s["team"], s["checkpoints"]) for s in board] == [
        (1, "Team B", 2),
        (2, "Team A", 2),
    ]
    assert board[0]["uplink_share_left"] == pytest.approx(0.7)
    assert board[1]["uplink_share_left"] == pytest.approx(0.4)
    with portal.on_master():
        sources = {(r.instance_id, r.remote_run_id) for r in db.session.scalars(select(Run))}
    assert sources == {(portal.instance_id, run_a), (portal.other_instance_id, run_b)}
