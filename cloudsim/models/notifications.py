"""Run notifications: webhooks, the events a run produced, their deliveries, e-mail opt-outs."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import JSON, ForeignKey, String, Text, UniqueConstraint
from sqlalchemy.orm import Mapped, mapped_column

from cloudsim.crypto import EncryptedText
from cloudsim.models.base import Base, UTCDateTime, utcnow


class Webhook(Base):
    """An URL every run event is POSTed to, signed with its secret (encrypted at rest)."""

    __tablename__ = "webhooks"

    id: Mapped[int] = mapped_column(primary_key=True)
    url: Mapped[str] = mapped_column(String(500))
    secret: Mapped[str] = mapped_column(EncryptedText)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)

    def __repr__(self) -> str:
        return f"<Webhook {self.id} {self.url!r}>"


class RunNotice(Base):
    """One event of one run (started, ended, failed, needs_review): made once, never sent twice."""

    __tablename__ = "run_notices"
    __table_args__ = (UniqueConstraint("run_id", "event"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), index=True)
    event: Mapped[str] = mapped_column(String(16))
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    # the JSON event, fixed when the event happened: every retry sends the same body
    payload: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    # ids of the people already mailed: a retried e-mail job skips them
    mailed: Mapped[list[int]] = mapped_column(JSON, default=list)
    mail_attempts: Mapped[int] = mapped_column(default=0)
    mail_error: Mapped[str | None] = mapped_column(Text)
    mailed_at: Mapped[datetime | None] = mapped_column(UTCDateTime)

    def __repr__(self) -> str:
        return f"<RunNotice {self.id} run={self.run_id} {self.event}>"


class WebhookDelivery(Base):
    """One event sent to one webhook: its attempts, last status and error."""

    __tablename__ = "webhook_deliveries"
    __table_args__ = (UniqueConstraint("notice_id", "webhook_id"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    notice_id: Mapped[int] = mapped_column(
        ForeignKey("run_notices.id", ondelete="CASCADE"), index=True
    )
    # kept (with its URL) when the webhook is removed: the list still says where it went
    webhook_id: Mapped[int | None] = mapped_column(ForeignKey("webhooks.id", ondelete="SET NULL"))
    event: Mapped[str] = mapped_column(String(16))
    run_id: Mapped[int] = mapped_column()
    url: Mapped[str] = mapped_column(String(500))
    status_code: Mapped[int | None] = mapped_column()
    attempts: Mapped[int] = mapped_column(default=0)
    last_error: Mapped[str | None] = mapped_column(Text)
    # one {"at", "status_code", "error"} per attempt, oldest first
    history: Mapped[list[dict[str, Any]]] = mapped_column(JSON, default=list)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    attempted_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    delivered_at: Mapped[datetime | None] = mapped_column(UTCDateTime)

    def __repr__(self) -> str:
        return f"<WebhookDelivery {self.id} {self.event} run={self.run_id} {self.status_code}>"


class EmailOptOut(Base):
    """A person who asked for no run e-mails."""

    __tablename__ = "email_opt_outs"

    user_id: Mapped[int] = mapped_column(
        ForeignKey("users.id", ondelete="CASCADE"), primary_key=True
    )
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
