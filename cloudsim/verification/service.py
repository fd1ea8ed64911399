"""Which runs are verified, queued or held, and the one place their verification changes."""

from __future__ import annotations

from typing import Any

from sqlalchemy import ColumnElement, Select, or_, select, update

from cloudsim.audit.service import record
from cloudsim.auth.policy import SYSTEM, Actor
from cloudsim.competition.lifecycle import RunJob
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.jobs.service import enqueue
from cloudsim.models import Run, RunState, Verification, utcnow

VERIFY = "run.verify"
SWEEP = "cloudsim.verification.sweep"
SWEEP_BATCH = 100
MAX_REASON = 4000
# what the leaderboard and the portal show for each state (None: not verified yet)
LABELS = {
    None: "unverified",
    Verification.VERIFYING: "verifying",
    Verification.VERIFIED: "verified",
    Verification.HELD: "held for review",
    Verification.ACCEPTED: "accepted by an officer",
}


def label(verification: Verification | None) -> str:
    """Return how a run's verification is shown."""
    return LABELS[verification]


def ready_to_verify() -> Select[Any]:
    """Return the ids of the finished runs whose logs are all there and no verification has
    started: a master's own (its stop job stored the logs), or uploaded and complete."""
    return (
        select(Run.id)
        .where(
            Run.state == RunState.FINISHED,
            Run.verification.is_(None),
            Run.invalidated_at.is_(None),
            or_(Run.instance_id.is_(None), Run.logs_complete_at.is_not(None)),
        )
        .order_by(Run.finished_at, Run.id)
    )


def request_verification(run_id: int, actor: Actor = SYSTEM, *, again: bool = False) -> bool:
    """Mark a finished run verifying and queue its job, unless it is already (`again`: unless
    it is queued now); return whether a job was queued. The caller commits."""
    state = (
        Run.verification.is_distinct_from(Verification.VERIFYING)
        if again
        else Run.verification.is_(None)
    )
    claimed = db.session.execute(
        update(Run)
        .where(Run.id == run_id, Run.state == RunState.FINISHED, state)
        .values(verification=Verification.VERIFYING, verification_reason=None, verified_at=None)
        .execution_options(synchronize_session="fetch")
    )
    if claimed.rowcount != 1:  # type: ignore[attr-defined]
        return False  # another request (or the sweep) queued it, or it is not finished
    team_id = db.session.scalar(select(Run.team_id).where(Run.id == run_id))
    enqueue(VERIFY, actor, RunJob(run_id), team_id=team_id)
    return True


def sweep() -> int:
    """Queue the verification of every finished run that has none yet; return how many."""
    ids = list(db.session.scalars(ready_to_verify().limit(SWEEP_BATCH)))
    return sum(request_verification(run_id) for run_id in ids)


def decide(run: Run, verdict: Verification, reason: str | None) -> None:
    """Record what the replay found (audited)."""
    run.verification = verdict
    run.verification_reason = reason[:MAX_REASON] if reason else None
    run.verified_at = utcnow()
    record(
        "run.verify",
        SYSTEM,
        target_type="run",
        target_id=run.id,
        team_id=run.team_id,
        outcome=verdict.value,
        reason=run.verification_reason,
    )
    db.session.flush()


def ranks(config: Config) -> ColumnElement[bool]:
    """Return the condition on a finished, not invalidated run for it to be ranked: never while
    held; while unverified only if CLOUDSIM_RANK_UNVERIFIED."""
    counted = Run.verification.in_((Verification.VERIFIED, Verification.ACCEPTED))
    if not config.rank_unverified:
        return counted
    return or_(counted, Run.verification.is_(None), Run.verification == Verification.VERIFYING)


def unverified() -> ColumnElement[bool]:
    """Return the condition on a run that it is not (yet) verified nor accepted, nor held."""
    return or_(Run.verification.is_(None), Run.verification == Verification.VERIFYING)


def held() -> ColumnElement[bool]:
    """Return the condition on a run that it is held for review."""
    return Run.verification == Verification.HELD
