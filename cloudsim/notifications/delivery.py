"""Send a run notice: e-mail its people over SMTP and POST its signed event to each webhook.

Celery tasks, each retried with a doubling wait (CLOUDSIM_NOTIFY_RETRY_SECONDS, up to
CLOUDSIM_NOTIFY_ATTEMPTS tries). Each try is recorded in its own short transaction before
the retry is scheduled, so the deliveries list shows every attempt; a person already mailed
and a delivery already answered 2xx are never sent again.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import logging
import smtplib
import ssl
import urllib.error
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import redis
from celery import shared_task
from flask import current_app
from redis.exceptions import LockError
from sqlalchemy import select

from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.models import Run, RunNotice, Webhook, WebhookDelivery, utcnow
from cloudsim.notifications.service import recipients
from cloudsim.notifications.summary import run_email

log = logging.getLogger(__name__)
MAIL_TASK = "cloudsim.notifications.mail"
HOOK_TASK = "cloudsim.notifications.webhook"
SIGNATURE_HEADER = "X-CloudSim-Signature"
TIMEOUT = 10.0  # seconds for one SMTP conversation step or one webhook answer
LOCK_SECONDS = 300  # longer than one try can take (a few SMTP steps or one POST)
MAX_WAIT = 3600.0


def _config() -> Config:
    return current_app.config["CLOUDSIM"]  # type: ignore[no-any-return]


@contextmanager
def _alone(config: Config, name: str) -> Iterator[bool]:
    """Hold a Redis lock for one notice or delivery; yield whether this task got it.

    A resend and a retry of the same task may run at once: only one of them sends.
    """
    lock = redis.Redis.from_url(config.effective_redis_url).lock(
        f"cloudsim:notify:{name}", timeout=LOCK_SECONDS
    )
    got = lock.acquire(blocking=False)
    try:
        yield got
    finally:
        if got:
            try:
                lock.release()
            except LockError:  # it expired: the other task may already hold it
                pass


def _wait(config: Config, attempts: int) -> float:
    return float(min(config.notify_retry_seconds * 2 ** max(attempts - 1, 0), MAX_WAIT))


def send_notice(notice_id: int, delivery_ids: list[int]) -> None:
    """Queue a committed notice's e-mails and webhook deliveries (no SQL: after a commit)."""
    mail_run_notice.delay(notice_id)
    for delivery_id in delivery_ids:
        deliver_webhook.delay(delivery_id)


def resend_pending() -> int:
    """Queue again every notice not mailed and every delivery not accepted, within their tries;
    return how many were queued."""
    config = _config()
    notices = select(RunNotice.id).where(
        RunNotice.mailed_at.is_(None), RunNotice.mail_attempts < config.notify_attempts
    )
    hooks = select(WebhookDelivery.id).where(
        WebhookDelivery.delivered_at.is_(None),
        WebhookDelivery.webhook_id.is_not(None),
        WebhookDelivery.attempts < config.notify_attempts,
    )
    queued = 0
    for notice_id in db.session.scalars(notices):
        mail_run_notice.delay(notice_id)
        queued += 1
    for delivery_id in db.session.scalars(hooks):
        deliver_webhook.delay(delivery_id)
        queued += 1
    return queued


def sign(secret: str, body: bytes) -> str:
    """Return the signature header's value: sha256= and the body's hex HMAC-SHA256."""
    return "sha256=" + hmac.new(secret.encode(), body, hashlib.sha256).hexdigest()


def _masked(text: str, config: Config) -> str:
    secret = config.smtp_password
    return text.replace(secret, "***") if secret else text


def _smtp(config: Config) -> smtplib.SMTP:
    server = smtplib.SMTP(config.smtp_host, config.smtp_port, timeout=TIMEOUT)
    try:
        if config.smtp_starttls:
            server.starttls(context=ssl.create_default_context())
        if config.smtp_username:
            server.login(config.smtp_username, config.smtp_password)
    except BaseException:
        server.close()  # a refused upgrade or login leaves no connection open
        raise
    return server


@shared_task(bind=True, name=MAIL_TASK, max_retries=None)
def mail_run_notice(self: Any, notice_id: int) -> int:
    """E-mail a notice to each of its people not mailed yet; return how many were mailed."""
    config = _config()
    with _alone(config, f"mail:{notice_id}") as alone:
        return _mail(self, config, notice_id) if alone else 0


def _mail(task: Any, config: Config, notice_id: int) -> int:
    notice = db.session.get(RunNotice, notice_id)
    if notice is None or notice.mailed_at is not None:
        return 0
    if not config.smtp_host:
        notice.mailed_at = utcnow()
        notice.mail_error = "no SMTP server configured"
        return 0
    run = db.session.get(Run, notice.run_id)
    people = [p for p in recipients(run) if p.id not in notice.mailed] if run else []
    sent = 0
    try:
        if people:
            with _smtp(config) as server:
                for person in people:
                    server.send_message(run_email(notice.payload, config.smtp_sender, person.email))
                    # each person is recorded at once: a retry after a failure skips them
                    notice.mailed = [*notice.mailed, person.id]
                    db.session.commit()
                    sent += 1
        notice.mailed_at = utcnow()
        notice.mail_error = None
        return sent
    except (OSError, smtplib.SMTPException) as exc:
        db.session.rollback()
        notice = db.session.get(RunNotice, notice_id)
        assert notice is not None
        notice.mail_attempts += 1
        error = _masked(f"{type(exc).__name__}: {exc}", config)[:2000]
        notice.mail_error = error
        attempts = notice.mail_attempts
        db.session.commit()
        log.warning(
            "run notice %s: e-mail try %s failed: %s", notice_id, attempts, notice.mail_error
        )
        if attempts >= config.notify_attempts:
            return sent
        raise task.retry(countdown=_wait(config, attempts)) from None


def _post(url: str, body: bytes, headers: dict[str, str]) -> tuple[int | None, str | None]:
    # the URL was checked to be http(s) when the webhook was added
    request = urllib.request.Request(url, data=body, headers=headers, method="POST")  # noqa: S310
    try:
        with urllib.request.urlopen(request, timeout=TIMEOUT) as answer:  # noqa: S310
            return answer.status, None
    except urllib.error.HTTPError as exc:
        return exc.code, f"HTTP {exc.code}"
    except (OSError, ValueError) as exc:
        return None, f"{type(exc).__name__}: {exc}"


@shared_task(bind=True, name=HOOK_TASK, max_retries=None)
def deliver_webhook(self: Any, delivery_id: int) -> bool:
    """POST a notice's signed event to one webhook; return whether it was accepted."""
    config = _config()
    with _alone(config, f"hook:{delivery_id}") as alone:
        return _deliver(self, config, delivery_id) if alone else False


def _deliver(task: Any, config: Config, delivery_id: int) -> bool:
    delivery = db.session.get(WebhookDelivery, delivery_id)
    if delivery is None or delivery.delivered_at is not None:
        return delivery is not None
    hook = db.session.get(Webhook, delivery.webhook_id) if delivery.webhook_id else None
    if hook is None:
        delivery.last_error = "the webhook was removed"
        return False
    notice = db.session.get(RunNotice, delivery.notice_id)
    assert notice is not None
    body = json.dumps(notice.payload, sort_keys=True).encode()
    headers = {
        "Content-Type": "application/json",
        "User-Agent": "CloudSim-Webhook",
        "X-CloudSim-Event": notice.payload["event"],
        "X-CloudSim-Delivery": str(delivery.id),
        SIGNATURE_HEADER: sign(hook.secret, body),
    }
    status, error = _post(hook.url, body, headers)
    ok = status is not None and 200 <= status < 300
    now = utcnow()
    delivery.attempts += 1
    delivery.status_code = status
    delivery.attempted_at = now
    delivery.last_error = error
    delivery.history = [
        *delivery.history,
        {"at": now.isoformat(), "status_code": status, "error": error},
    ]
    if ok:
        delivery.delivered_at = now
        return True
    attempts = delivery.attempts
    db.session.commit()  # the try is recorded before the retry is scheduled
    if attempts >= config.notify_attempts:
        return False
    raise task.retry(countdown=_wait(config, attempts))
