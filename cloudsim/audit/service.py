"""Record audit events and query the trail."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from flask import has_request_context, request
from sqlalchemy import Select, select

from cloudsim.extensions import db

if TYPE_CHECKING:
    from cloudsim.auth.policy import Actor
from cloudsim.models import AuditEvent, Role, User


def record(
    action: str,
    actor: Actor | None,
    *,
    target_type: str | None = None,
    target_id: object = None,
    team_id: int | None = None,
    **details: Any,
) -> AuditEvent:
    """Add an audit event to the current transaction (committed with the change it records).

    `actor` is None only for someone not logged in (a failed login).
    """
    event = AuditEvent(
        actor_id=actor.id if actor else None,
        actor=actor.email if actor else "anonymous",
        action=action,
        target_type=target_type,
        target_id=None if target_id is None else str(target_id),
        team_id=team_id,
        details=details,
        address=request.remote_addr if has_request_context() else None,
    )
    db.session.add(event)
    return event


def visible_events(viewer: User, *, action: str | None = None) -> Select[AuditEvent]:
    """Return a query for the events `viewer` may see, newest first."""
    query = select(AuditEvent).order_by(AuditEvent.id.desc())
    if not viewer.has_role(Role.OFFICER):
        query = query.where(AuditEvent.team_id == viewer.team_id, AuditEvent.team_id.is_not(None))
    if action:
        query = query.where(AuditEvent.action == action)
    return query
