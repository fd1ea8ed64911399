"""Run notifications: record a run's event once, and manage webhooks and e-mail opt-outs.

Everything here only flushes: the caller's transaction (the run job that moved the run) owns
the commit, and the e-mails and webhook deliveries are sent by Celery tasks only once it has
committed, so a dead SMTP server or webhook never delays or fails a run.
"""

from __future__ import annotations

import logging
import secrets
from typing import Any
from urllib.parse import urlsplit

from sqlalchemy import Select, event, select
from sqlalchemy.orm import Session

from cloudsim.auth.policy import Actor, require_role
from cloudsim.errors import InvalidInput, NotFound
from cloudsim.extensions import db
from cloudsim.models import (
    EmailOptOut,
    Role,
    Run,
    RunNotice,
    RunState,
    User,
    Webhook,
    WebhookDelivery,
    utcnow,
)
from cloudsim.notifications.summary import run_summary

log = logging.getLogger(__name__)
EVENTS = ("started", "ended", "failed", "needs_review")
UNSENT = "cloudsim.unsent_notices"  # session.info: (notice id, delivery ids) sent after commit
MAX_URL = 500


def notify_run_event(run: Run, event_name: str) -> RunNotice | None:
    """Record a run's event once and have it mailed and posted after the commit.

    Returns None when the event was recorded before (nothing is sent twice).
    """
    if event_name not in EVENTS:
        raise InvalidInput(f"unknown run event {event_name!r}; known: {', '.join(EVENTS)}")
    found = db.session.scalar(
        select(RunNotice.id).where(RunNotice.run_id == run.id, RunNotice.event == event_name)
    )
    if found is not None:
        return None
    notice = RunNotice(run_id=run.id, event=event_name, mailed=[], created_at=utcnow())
    notice.payload = {"event": f"run.{event_name}", "at": notice.created_at.isoformat()}
    db.session.add(notice)
    db.session.flush()
    notice.payload = {**notice.payload, "notice_id": notice.id, "run": run_summary(run)}
    sends = [
        WebhookDelivery(
            notice_id=notice.id,
            webhook_id=hook.id,
            event=event_name,
            run_id=run.id,
            url=hook.url,
            history=[],
        )
        for hook in db.session.scalars(select(Webhook).order_by(Webhook.id))
    ]
    db.session.add_all(sends)
    db.session.flush()
    db.session.info.setdefault(UNSENT, []).append((notice.id, [d.id for d in sends]))
    return notice


def run_ended_event(run: Run) -> str:
    """Return the event a run's end is: failed for an error, ended otherwise (also when an
    officer settles a run in review)."""
    return "failed" if run.state == RunState.ERROR else "ended"


@event.listens_for(Session, "after_commit")
def _send_committed(session: Session) -> None:
    ids = session.info.pop(UNSENT, [])
    if not ids:
        return
    from cloudsim.notifications.delivery import send_notice

    for notice_id, delivery_ids in ids:
        try:
            send_notice(notice_id, delivery_ids)
        except Exception:  # the queue is down: the run goes on; `cloudsim notify resend`
            log.warning("could not queue run notice %s; it waits for a resend", notice_id)


@event.listens_for(Session, "after_rollback")
def _forget_rolled_back(session: Session) -> None:
    session.info.pop(UNSENT, None)


# --- webhooks (admins) ---------------------------------------------------------------------


def _valid_url(url: str) -> str:
    url = (url or "").strip()
    parts = urlsplit(url)
    if len(url) > MAX_URL or parts.scheme not in ("http", "https") or not parts.hostname:
        raise InvalidInput(f"a webhook URL is http(s)://HOST/PATH, at most {MAX_URL} characters")
    return url


def add_webhook(actor: Actor, url: str, secret: str | None = None) -> tuple[Webhook, str]:
    """Add a webhook (admins); return it and its signing secret (generated when not given)."""
    require_role(actor, Role.ADMIN, "add webhooks")
    secret = (secret or "").strip() or secrets.token_urlsafe(32)
    if not 16 <= len(secret) <= 200:
        raise InvalidInput("a webhook secret has 16 to 200 characters")
    hook = Webhook(url=_valid_url(url), secret=secret)
    db.session.add(hook)
    db.session.flush()
    return hook, secret


def remove_webhook(actor: Actor, webhook_id: int) -> None:
    """Remove a webhook (admins); its past deliveries stay listed."""
    require_role(actor, Role.ADMIN, "remove webhooks")
    hook = db.session.get(Webhook, webhook_id)
    if hook is None:
        raise NotFound(f"webhook {webhook_id} not found")
    db.session.delete(hook)
    db.session.flush()


def webhooks(actor: Actor) -> list[Webhook]:
    """Return every webhook (admins)."""
    require_role(actor, Role.ADMIN, "list webhooks")
    return list(db.session.scalars(select(Webhook).order_by(Webhook.id)))


def deliveries(actor: Actor) -> Select[Any]:
    """Return the query of every webhook delivery, newest first (admins)."""
    require_role(actor, Role.ADMIN, "list webhook deliveries")
    return select(WebhookDelivery).order_by(WebhookDelivery.id.desc())


# --- e-mail opt-out -------------------------------------------------------------------------


def wants_run_emails(user: User) -> bool:
    """Tell whether a person gets run e-mails."""
    return db.session.get(EmailOptOut, user.id) is None


def set_run_emails(user: User, wanted: bool) -> None:
    """Opt a person in or out of run e-mails."""
    row = db.session.get(EmailOptOut, user.id)
    if wanted and row is not None:
        db.session.delete(row)
    elif not wanted and row is None:
        db.session.add(EmailOptOut(user_id=user.id))
    db.session.flush()


def recipients(run: Run) -> list[User]:
    """Return who is mailed about a run: its team's active members and the officers, minus
    those who opted out."""
    opted_out = select(EmailOptOut.user_id)
    query = (
        select(User)
        .where(
            User.active.is_(True),
            (User.team_id == run.team_id) | (User.role == Role.OFFICER),
            User.id.not_in(opted_out),
        )
        .order_by(User.id)
    )
    return list(db.session.scalars(query))
