"""Officers' side of results integrity: what the portal refused, and their word on a run
(a note, an invalidation that takes it out of the ranking, the acceptance of a run its
verification held), every change audited."""

from __future__ import annotations

from typing import Any

from sqlalchemy import Select, select
from sqlalchemy.orm import selectinload

from cloudsim.audit.service import record
from cloudsim.auth.policy import Actor, require_role
from cloudsim.competition.runs import get_run
from cloudsim.errors import Conflict, InvalidInput
from cloudsim.extensions import db
from cloudsim.models import (
    PortalRefusal,
    Role,
    Run,
    RunState,
    TeamInstance,
    Verification,
    utcnow,
)
from cloudsim.portal.ingest import Refused, counted_run

MAX_NOTE = 2000


def record_refusal(instance: TeamInstance | None, remote_id: int | None, refused: Refused) -> None:
    """Keep a refusal for officers to see (in the caller's transaction)."""
    db.session.add(
        PortalRefusal(
            instance_id=instance.id if instance is not None else None,
            team_id=instance.team_id if instance is not None else None,
            remote_run_id=remote_id,
            run_id=refused.run_id,
            reason=str(refused),
            detail=refused.detail,
        )
    )
    db.session.flush()


def refusals(actor: Actor) -> Select[PortalRefusal]:
    """Return every refused upload, newest first (officers)."""
    require_role(actor, Role.OFFICER, "see refused uploads")
    return (
        select(PortalRefusal)
        .options(selectinload(PortalRefusal.instance))
        .order_by(PortalRefusal.id.desc())
    )


def _text(value: str | None, what: str) -> str | None:
    value = " ".join((value or "").split()) or None
    if value is not None and len(value) > MAX_NOTE:
        raise InvalidInput(f"{what} is at most {MAX_NOTE} characters")
    return value


def _check_counted_alone(run: Run) -> None:
    """Refuse to count a finished run again while another finished run of its task counts."""
    if run.state != RunState.FINISHED:
        return
    other = counted_run(run.task_id, other_than=run.id)
    if other is not None:
        raise Conflict(
            f"run {other.id} of the same task counts now; invalidate it before reinstating this one"
        )


def _accept(actor: Actor, run: Run, why: str | None) -> None:
    """Accept a run its verification held: it ranks again (the held reason is kept)."""
    if run.verification is Verification.ACCEPTED:
        return
    if run.verification is not Verification.HELD:
        shown = run.verification.value if run.verification else "not verified yet"
        raise Conflict(f"run {run.id} is not held for review ({shown}): nothing to accept")
    run.verification, run.verified_at = Verification.ACCEPTED, utcnow()
    record(
        "run.accept",
        actor,
        target_type="run",
        target_id=run.id,
        team_id=run.team_id,
        held_for=run.verification_reason,
        reason=why,
    )


def review_run(
    actor: Actor,
    run_id: int,
    *,
    note: Any = ...,
    invalidated: bool | None = None,
    reason: str | None = None,
    accepted: bool | None = None,
) -> Run:
    """Set an officer's note on a run, invalidate it (with a reason) or count it again, or
    accept a run held for review (it is ranked again)."""
    require_role(actor, Role.OFFICER, "review runs")
    run = get_run(actor, run_id)
    if note is not ...:
        text = _text(note, "a note")
        if text != run.officer_note:
            run.officer_note = text
            record(
                "run.annotate",
                actor,
                target_type="run",
                target_id=run.id,
                team_id=run.team_id,
                note=text,
            )
    if invalidated is True:
        why = _text(reason, "the reason")
        if why is None:
            raise InvalidInput("say why the run is invalidated (reason)")
        if run.invalidated_at is None or run.invalid_reason != why:
            run.invalidated_at, run.invalid_reason = run.invalidated_at or utcnow(), why
            record(
                "run.invalidate",
                actor,
                target_type="run",
                target_id=run.id,
                team_id=run.team_id,
                reason=why,
            )
    elif invalidated is False and run.invalidated_at is not None:
        _check_counted_alone(run)
        run.invalidated_at, run.invalid_reason = None, None
        record("run.reinstate", actor, target_type="run", target_id=run.id, team_id=run.team_id)
    if accepted:
        _accept(actor, run, _text(reason, "the reason"))
    db.session.flush()
    return run
