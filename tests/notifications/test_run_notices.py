"""Run notices reach people: e-mails through a real SMTP server, signed events to a real
webhook on loopback, sent by Celery tasks after the run's change commits, retried, listed."""

from __future__ import annotations

import hashlib
import hmac
import json
import socket
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from email import message_from_bytes
from email.message import Message
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

import pytest
from aiosmtpd.controller import Controller
from aiosmtpd.smtp import AuthResult, LoginPassword
from celery.contrib.testing.worker import start_worker
from flask import Flask
from flask.testing import FlaskClient
from sqlalchemy import select

from cloudsim.auth.policy import SYSTEM
from cloudsim.competition import lifecycle
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import Job, Role, Run, RunNotice, RunState, Team, User, WebhookDelivery
from cloudsim.notifications.delivery import resend_pending
from cloudsim.notifications.service import UNSENT, add_webhook, notify_run_event, run_ended_event
from tests.competition.support import open_task
from tests.conftest import csrf_token, log_in, make_user, running_app, token_for
from tests.support.servers import wait_for
from tests.support.workers import job_finished
from tests.web.test_query_counts import counting

SECRET = "a-webhook-secret-of-some-length"


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@dataclass
class Mailbox:
    """What the test's SMTP server received: one (recipients, message) per e-mail."""

    port: int
    mails: list[tuple[list[str], Message]] = field(default_factory=list)

    async def handle_DATA(self, server: Any, session: Any, envelope: Any) -> str:
        self.mails.append((list(envelope.rcpt_tos), message_from_bytes(envelope.content)))
        return "250 OK"

    def to(self, address: str) -> list[Message]:
        return [m for rcpt, m in self.mails if address in rcpt]


@pytest.fixture
def mailbox() -> Iterator[Mailbox]:
    box = Mailbox(free_port())
    controller = Controller(box, hostname="127.0.0.1", port=box.port)
    controller.start()
    yield box
    controller.stop()


@dataclass
class Hook:
    """A webhook receiver on loopback: answers `statuses` in turn (then 200), keeps requests."""

    url: str = ""
    statuses: list[int] = field(default_factory=list)
    received: list[tuple[dict[str, str], bytes, int]] = field(default_factory=list)


@pytest.fixture
def hook() -> Iterator[Hook]:
    state = Hook()

    class Handler(BaseHTTPRequestHandler):
        def do_POST(self) -> None:
            body = self.rfile.read(int(self.headers["Content-Length"]))
            status = state.statuses.pop(0) if state.statuses else 200
            state.received.append(({k.lower(): v for k, v in self.headers.items()}, body, status))
            self.send_response(status)
            self.send_header("Content-Length", "0")
            self.end_headers()

        def log_message(self, *args: Any) -> None:
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    state.url = f"http://127.0.0.1:{server.server_address[1]}/cloudsim-events"
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield state
    server.shutdown()
    server.server_close()
    thread.join()


@pytest.fixture
def app(make_config: Callable[..., Config], mailbox: Mailbox) -> Iterator[Flask]:
    config = make_config(
        smtp_host="127.0.0.1",
        smtp_port=mailbox.port,
        smtp_sender="cloudsim@example.org",
        public_url="https://cloudsim.example.org",
        notify_retry_seconds=0.2,
    )
    with running_app(config) as app:
        yield app


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


def running_run(team: Team) -> Run:
    """A run of an open task of the team, moved to running by the lifecycle (and told)."""
    task = open_task(team.id)
    run = lifecycle.new_run(task_id=task.id, team_id=team.id)
    db.session.add(run)
    db.session.flush()
    lifecycle.running(run)
    notify_run_event(run, "started")
    db.session.commit()
    return run


def end(run: Run) -> None:
    """End a run as its stop job does: scored, ended, told, committed."""
    run.score, run.falls, run.sim_seconds = 3, 1, 42.0
    run.uplink_bits_used, run.downlink_bits_used = 400_000, 1_000_000
    lifecycle.ended(run, None, failed=False)
    notify_run_event(run, run_ended_event(run))
    db.session.commit()


def opt_out(client: FlaskClient, user: User) -> None:
    """Untick "run e-mails" on the account page and save it, as a person would."""
    log_in(client, user)
    page = client.get("/account").get_data(as_text=True)
    assert 'action="/account/run-emails"' in page and 'name="run_emails"' in page
    response = client.post("/account/run-emails", data={"csrf_token": csrf_token(page)})
    assert response.status_code == 302
    page = client.get("/account").get_data(as_text=True)
    assert "Run e-mails off." in page


def test_a_run_s_start_and_end_are_mailed_and_posted_signed(
    app: Flask, team_a: Team, team_b: Team, mailbox: Mailbox, hook: Hook, worker: None
) -> None:
    member, quiet = make_user(Role.USER, team_a), make_user(Role.USER, team_a)
    stranger, officer = make_user(Role.USER, team_b), make_user(Role.OFFICER)
    admin = make_user(Role.ADMIN)
    api = app.test_client()
    added = api.post(
        "/api/v1/webhooks", json={"url": hook.url, "secret": SECRET}, headers=token_for(admin)
    )
    assert added.status_code == 201, added.get_json()
    assert added.get_json()["secret"] == SECRET
    listed = api.get("/api/v1/webhooks", headers=token_for(admin)).get_json()
    assert [h["url"] for h in listed] == [hook.url] and "secret" not in listed[0]
    opt_out(app.test_client(), quiet)

    run = running_run(team_a)
    end(run)

    wait_for(lambda: len(mailbox.mails) == 4, 30, "4 e-mails: started and ended, 2 people")
    assert sorted(r[0] for r, _ in mailbox.mails) == sorted([member.email, officer.email] * 2)
    for nobody in (quiet, stranger, admin):
        assert mailbox.to(nobody.email) == []
    ended = [m for m in mailbox.to(member.email) if "ended" in m["Subject"]]
    assert len(ended) == 1
    text = ended[0].get_payload()
    assert isinstance(text, str)
    for line in (
        "Score: 3",
        "Falls: 1",
        "Simulated time: 42.0 s of 1800 s",
        "Bits left: 600000 up, 7000000 down",
        f"Replay: https://cloudsim.example.org/runs/{run.id}/view",
    ):
        assert line in text, text

    wait_for(lambda: len(hook.received) == 2, 30, "the webhook's 2 events")
    events = []
    for headers, body, _ in hook.received:
        expected = "sha256=" + hmac.new(SECRET.encode(), body, hashlib.sha256).hexdigest()
        assert hmac.compare_digest(headers["x-cloudsim-signature"], expected)
        events.append(json.loads(body))
    by_event = {e["event"]: e for e in events}
    assert set(by_event) == {"run.started", "run.ended"}
    summary = by_event["run.ended"]["run"]
    assert (summary["id"], summary["score"], summary["falls"], summary["sim_seconds"]) == (
        run.id,
        3,
        1,
        42.0,
    )
    assert (summary["uplink_bits_left"], summary["downlink_bits_left"]) == (600_000, 7_000_000)

    def delivered() -> list[dict[str, Any]]:
        answer = api.get("/api/v1/webhook-deliveries", headers=token_for(admin)).get_json()
        return answer if all(d["delivered_at"] for d in answer) else []

    listed = wait_for(delivered, 30, "both deliveries recorded")
    assert sorted((d["event"], d["status_code"], d["attempts"]) for d in listed) == [  # type: ignore[union-attr]
        ("run.ended", 200, 1),
        ("run.started", 200, 1),
    ]
    # nothing is told twice: a second report of the same end adds nothing
    assert notify_run_event(run, "ended") is None
    assert db.session.scalar(select(RunNotice).where(RunNotice.event == "ended")) is not None


def test_a_failing_webhook_is_retried_and_both_tries_are_listed(
    app: Flask, team_a: Team, mailbox: Mailbox, hook: Hook, worker: None
) -> None:
    admin = make_user(Role.ADMIN)
    client = app.test_client()
    log_in(client, admin)
    page = client.get("/admin/webhooks").get_data(as_text=True)
    form = {"url": hook.url, "secret": SECRET, "csrf_token": csrf_token(page)}
    assert client.post("/admin/webhooks", data=form).status_code == 200
    hook.statuses = [500]
    run = running_run(team_a)

    def accepted() -> WebhookDelivery | None:
        db.session.expire_all()
        found = db.session.scalar(select(WebhookDelivery).where(WebhookDelivery.run_id == run.id))
        return found if found is not None and found.delivered_at is not None else None

    delivery = wait_for(accepted, 30, "the delivery to be accepted on its second try")
    assert isinstance(delivery, WebhookDelivery)
    assert (delivery.attempts, delivery.status_code) == (2, 200)
    assert [a["status_code"] for a in delivery.history] == [500, 200]
    assert [status for _, _, status in hook.received] == [500, 200]
    # the same body, signed the same, both times
    assert hook.received[0][1] == hook.received[1][1]
    page = client.get("/admin/webhooks").get_data(as_text=True)
    assert "run.started" in page and "200 delivered" in page
    assert ": 500</li>" in page and ": 200</li>" in page  # each try on the list
    # removed through its page, the webhook gets nothing more; its deliveries stay listed
    hook_id = delivery.webhook_id
    removed = client.post(
        f"/admin/webhooks/{hook_id}/delete", data={"csrf_token": csrf_token(page)}
    )
    assert removed.status_code == 302
    page = client.get("/admin/webhooks").get_data(as_text=True)
    assert "No webhooks." in page and ": 500</li>" in page
    end(run)
    events = db.session.scalars(
        select(WebhookDelivery.event).where(WebhookDelivery.run_id == run.id)
    )
    assert list(events) == ["started"]


def test_a_run_in_review_is_told_and_so_is_how_an_officer_settles_it(
    app: Flask, team_a: Team, mailbox: Mailbox, hook: Hook, worker: None
) -> None:
    """The real stop job on a run it cannot reach: the run goes to needs_review and its people
    and webhooks are told so (not "ended" or "failed"); the officer's settling, submitted on
    the run page, is told as the run's end."""
    member, officer = make_user(Role.USER, team_a), make_user(Role.OFFICER)
    add_webhook(SYSTEM, hook.url, SECRET)
    run = running_run(team_a)
    wait_for(lambda: len(mailbox.to(member.email)) == 1, 30, "the started e-mail")
    # the run has no constellation: its real stop job cannot reach it
    assert lifecycle.request_stop(run, "stop")
    stop = db.session.scalar(select(Job).where(Job.kind == "run.stop", Job.target_id == run.id))
    assert stop is not None
    job_finished(stop.id, 60)
    db.session.expire_all()
    assert db.session.get(Run, run.id).state == RunState.NEEDS_REVIEW  # type: ignore[union-attr]
    notices = db.session.scalars(select(RunNotice.event).where(RunNotice.run_id == run.id))
    assert sorted(notices) == ["needs_review", "started"]

    def mailed(address: str, words: str) -> list[Message]:
        return [m for m in mailbox.to(address) if words in m["Subject"]]

    wait_for(lambda: mailed(member.email, "review"), 30, "the member's review e-mail")
    wait_for(lambda: mailed(officer.email, "review"), 30, "the officer's review e-mail")
    [review] = mailed(member.email, "review")
    subject = f"CloudSim: run {run.id} of {run.task.name} needs an officer's review"
    assert review["Subject"] == subject
    text = review.get_payload()
    assert isinstance(text, str)
    assert "State: needs_review" in text and "An officer checks its logs" in text, text
    wait_for(lambda: len(hook.received) == 2, 30, "the started and needs_review events")
    body = json.loads(hook.received[1][1])
    assert (body["event"], body["run"]["state"]) == ("run.needs_review", "needs_review")
    assert hook.received[1][0]["x-cloudsim-event"] == "run.needs_review"
    assert not mailed(member.email, "failed") and not mailed(member.email, "ended")

    client = app.test_client()
    log_in(client, officer)
    page = client.get(f"/runs/{run.id}").get_data(as_text=True)
    token = csrf_token(page.split('id="settle"', 1)[1])
    settled = client.post(
        f"/runs/{run.id}/settle",
        data={"decision": "fail", "note": "sim never came back", "csrf_token": token},
    )
    assert settled.status_code == 302
    wait_for(lambda: mailed(member.email, "failed"), 30, "the member's failed e-mail")
    wait_for(lambda: len(hook.received) == 3, 30, "the failed event")
    body = json.loads(hook.received[2][1])
    assert (body["event"], body["run"]["state"]) == ("run.failed", "error")
    assert "constellation no longer exists" in body["run"]["error"]
    assert body["run"]["officer_note"] == "sim never came back"
    [failed] = mailed(member.email, "failed")
    assert "Officer's note: sim never came back" in str(failed.get_payload())


def test_a_dead_smtp_server_never_fails_the_run_and_its_tries_are_recorded(
    app: Flask, team_a: Team, worker: None
) -> None:
    make_user(Role.USER, team_a)
    config: Config = app.config["CLOUDSIM"]
    app.config["CLOUDSIM"] = replace(config, smtp_port=free_port())  # nothing listens there
    run = running_run(team_a)
    end(run)
    db.session.expire_all()
    assert db.session.get(Run, run.id).state == RunState.FINISHED  # type: ignore[union-attr]

    def tried_twice() -> RunNotice | None:
        db.session.expire_all()
        notice = db.session.scalar(
            select(RunNotice).where(RunNotice.run_id == run.id, RunNotice.event == "ended")
        )
        return notice if notice is not None and notice.mail_attempts >= 2 else None

    notice = wait_for(tried_twice, 30, "two failed e-mail tries recorded")
    assert isinstance(notice, RunNotice)
    assert notice.mailed_at is None and notice.mailed == []
    assert "ConnectionRefusedError" in (notice.mail_error or "")


def test_a_notice_the_queue_missed_is_sent_by_resend(
    app: Flask, team_a: Team, mailbox: Mailbox, hook: Hook, worker: None
) -> None:
    member = make_user(Role.USER, team_a)
    add_webhook(SYSTEM, hook.url, SECRET)
    task = open_task(team_a.id)
    run = lifecycle.new_run(task_id=task.id, team_id=team_a.id)
    db.session.add(run)
    db.session.flush()
    lifecycle.running(run)
    notify_run_event(run, "started")
    db.session.info.pop(UNSENT)  # as if the queue was down when the run job committed
    db.session.commit()
    assert mailbox.mails == [] and hook.received == []
    assert resend_pending() == 2  # its e-mails and its one delivery
    db.session.commit()
    wait_for(lambda: len(mailbox.to(member.email)) == 1, 30, "the resent e-mail")
    wait_for(lambda: len(hook.received) == 1, 30, "the resent event")


def test_the_smtp_login_is_used_and_never_logged(
    app: Flask, team_a: Team, worker: None, caplog: pytest.LogCaptureFixture
) -> None:
    member = make_user(Role.USER, team_a)
    password = "smtp-password-never-logged"
    logins: list[tuple[bytes, bool]] = []

    def authenticator(
        server: Any, session: Any, envelope: Any, mechanism: str, data: Any
    ) -> AuthResult:
        ok = isinstance(data, LoginPassword) and data.password == password.encode()
        logins.append((data.login, ok))
        return AuthResult(success=ok)

    box = Mailbox(free_port())
    controller = Controller(
        box,
        hostname="127.0.0.1",
        port=box.port,
        authenticator=authenticator,
        auth_require_tls=False,  # loopback only; production sets CLOUDSIM_SMTP_STARTTLS
    )
    controller.start()
    try:
        config: Config = app.config["CLOUDSIM"]
        app.config["CLOUDSIM"] = replace(
            config, smtp_port=box.port, smtp_username="cloudsim", smtp_password="wrong-password"
        )
        caplog.set_level("DEBUG")
        run = running_run(team_a)
        wait_for(lambda: logins, 30, "a refused login")
        assert logins[0] == (b"cloudsim", False) and box.mails == []
        app.config["CLOUDSIM"] = replace(
            config, smtp_port=box.port, smtp_username="cloudsim", smtp_password=password
        )
        wait_for(lambda: box.to(member.email), 30, "the e-mail after a good login (a retry)")
        assert logins[-1] == (b"cloudsim", True)
        assert notify_run_event(run, "started") is None
        assert "wrong-password" not in caplog.text and password not in caplog.text
    finally:
        controller.stop()


def test_the_deliveries_page_and_list_make_as_many_queries_for_more_rows(
    app: Flask, team_a: Team
) -> None:
    admin = make_user(Role.ADMIN)
    add_webhook(SYSTEM, "https://hooks.example.org/a", SECRET)
    client = app.test_client()
    log_in(client, admin)
    headers = token_for(admin)

    def counts() -> tuple[int, int]:
        db.session.commit()
        with counting() as page:
            assert client.get("/admin/webhooks").status_code == 200
        with counting() as listed:
            assert client.get("/api/v1/webhook-deliveries", headers=headers).status_code == 200
        return len(page), len(listed)

    notify_run_event(running_run(team_a), "ended")
    counts()  # the token's first use records itself once
    few = counts()
    for _ in range(3):
        notify_run_event(running_run(team_a), "ended")
    assert counts() == few
