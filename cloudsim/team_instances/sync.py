"""The master's side of propagation: what each instance must have (desired state), the job
that pushes it, and the hook that starts that job for the instances a change concerns.

A change to a user, an SSH key, a task, a team or a world starts one `team_instance.sync`
job per ready instance concerned, when the change commits (an officer, a key or a world
change: every instance). The periodic check (`poll.check_instances`) pushes the same state
to every ready instance too: that is the reconcile, which puts back what was changed on an
instance by hand and catches up an instance that was unreachable. A failure is the instance's alone
(its own job, its own call with a short timeout) and is shown on its page.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import Any

import redis
from flask import current_app
from redis.exceptions import LockError
from redis.lock import Lock
from sqlalchemy import event, inspect, or_, select
from sqlalchemy.orm import InstanceState as RowState
from sqlalchemy.orm import Session

from cloudsim.audit.service import record
from cloudsim.auth.policy import SYSTEM
from cloudsim.competition.season import SPEC_FIELDS
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.jobs.runner import JobContext, Payload, job_kind
from cloudsim.jobs.service import enqueue
from cloudsim.models import (
    InstanceState,
    Role,
    SshKey,
    Task,
    Team,
    TeamInstance,
    User,
    World,
    utcnow,
)
from cloudsim.team_instances.client import InstanceError, call

DIRTY = "cloudsim.team_instances.dirty"
# what a user's desired state holds (desired_state): changing anything else syncs nothing
SYNCED_USER_FIELDS = ("email", "name", "role", "active", "password_hash", "team_id")
EVERY_TEAM = -1  # a change that concerns every instance (officers, keys of unknown owners)
SYNC_JOB = "team_instance.sync"
SYNC_LOCK_SECONDS = 60  # longest a sync waits for another one of the same instance


def desired_state(instance: TeamInstance) -> dict[str, Any]:
    """Return what the instance must have: its team, its members and the officers (with
    their password hashes and SSH keys), the team's tasks, every world, and how it uploads
    its runs to this master's portal; JSON-ready."""
    team = instance.team
    wanted = User.role == Role.OFFICER
    if team is not None:
        wanted = or_(wanted, (User.role == Role.USER) & (User.team_id == team.id))
    users = db.session.scalars(select(User).where(wanted).order_by(User.id))
    tasks: list[Task] = (
        list(db.session.scalars(select(Task).where(Task.team_id == team.id).order_by(Task.id)))
        if team is not None
        else []
    )
    from cloudsim.portal.credentials import portal_settings

    return {
        "team": team.name if team is not None else None,
        # where and how the instance uploads its runs (URL, CA, pinned SHA-256, its token)
        "portal": portal_settings(instance, current_app.config["CLOUDSIM"]),
        "users": [
            {
                "email": user.email,
                "name": user.name,
                "role": user.role.value,
                "active": user.active,
                "password_hash": user.password_hash,
                "ssh_keys": [{"name": k.name, "public_key": k.public_key} for k in user.ssh_keys],
            }
            for user in users
        ],
        "tasks": [
            {"key": f"m{task.id}"} | {name: _plain(getattr(task, name)) for name in SPEC_FIELDS}
            for task in tasks
        ],
        "worlds": [
            {"name": w.name, "version": w.version, "digest": w.digest, "document": w.document}
            for w in db.session.scalars(select(World).order_by(World.name))
        ],
    }


def _plain(value: object) -> object:
    return value.isoformat() if isinstance(value, datetime) else value


def synced(instance: TeamInstance, answer: dict[str, Any]) -> None:
    """Record a sync the instance accepted, and what it changed (drift put back, or news)."""
    instance.last_sync_at, instance.sync_error = utcnow(), None
    instance.heard_at = instance.last_sync_at
    report = {key: list(answer.get(key) or []) for key in ("changed", "reported", "drift")}
    instance.sync_report = report
    if report["changed"]:
        record(
            "team_instance.sync",
            SYSTEM,
            target_type="team_instance",
            target_id=instance.id,
            team_id=instance.team_id,
            changed=report["changed"][:50],
        )
    if report["drift"]:
        # its own event, so that an officer can list every drift ever put back
        record(
            "team_instance.drift",
            SYSTEM,
            target_type="team_instance",
            target_id=instance.id,
            team_id=instance.team_id,
            put_back=report["drift"][:50],
        )


def sync_failed(instance: TeamInstance, error: str) -> None:
    """Record why the instance is behind (its last successful sync time stays)."""
    instance.sync_error = error


@dataclass(frozen=True)
class InstanceJob(Payload):
    """The payload of a team instance's jobs: which instance."""

    instance_id: int

    def about(self) -> tuple[str, int]:
        return ("team_instance", self.instance_id)


@job_kind(SYNC_JOB, payload=InstanceJob)
def sync_instance(ctx: JobContext, payload: InstanceJob) -> None:
    """Push the desired state to one instance; fail (and say why on its page) if it refuses."""
    from cloudsim.team_instances.poll import endpoint_of

    instance = ctx.load(TeamInstance, payload.instance_id)
    if instance.state != InstanceState.READY:
        ctx.log(f"{instance.name} is {instance.state.value}: the periodic check catches it up")
        return
    lock = sync_lock(instance.id)
    if not lock.acquire(blocking_timeout=SYNC_LOCK_SECONDS):
        raise InstanceError(f"another sync of {instance.name} held it for {SYNC_LOCK_SECONDS} s")
    try:
        ctx.checkpoint()  # read the desired state as it is now, not as before the wait
        endpoint = endpoint_of(instance, current_app.config["CLOUDSIM"])
        ctx.mask(endpoint.token)
        answer = call(endpoint, "PUT", "/instance/desired-state", desired_state(instance))
    except InstanceError as exc:
        sync_failed(instance, str(exc))
        ctx.checkpoint()
        raise
    finally:
        release(lock)
    synced(instance, answer)
    ctx.log(f"changed: {answer.get('changed') or 'nothing'}")


def sync_lock(instance_id: int) -> Lock:
    """Return the lock one instance's syncs take in turn (jobs and the reconcile alike).

    Two pushes at once would race on the instance (both creating the same new user); one
    after the other, each reads the desired state once it holds the lock, so the last one
    to run pushes the newest. It expires by itself if its holder dies.
    """
    config: Config = current_app.config["CLOUDSIM"]
    client = redis.Redis.from_url(config.effective_redis_url)
    return client.lock(f"cloudsim:team-instance:{instance_id}:sync", timeout=SYNC_LOCK_SECONDS)


def release(lock: Lock) -> None:
    """Release a sync lock, if it is still ours (it may have expired)."""
    try:
        lock.release()
    except LockError:
        pass


def _user_synced(user: User) -> bool:
    """Return whether a changed user changed what instances hold (a login's time does not)."""
    state: RowState[User] = inspect(user)
    return any(state.attrs[name].history.has_changes() for name in SYNCED_USER_FIELDS)


def _teams_of(row: object, created: bool = False) -> set[int]:
    """Return the teams whose instances a changed (or created) row concerns."""
    if isinstance(row, User):
        if row.role == Role.USER and row.team_id:
            return {row.team_id}
        role_moved = not created and inspect(row).attrs.role.history.has_changes()
        if row.role == Role.ADMIN and not role_moved:
            return set()  # admins are not propagated; one who was an officer leaves every instance
        return {EVERY_TEAM}
    if isinstance(row, SshKey):
        user = row.__dict__.get("user")  # never load during a flush
        if isinstance(user, User) and user.role == Role.USER and user.team_id:
            return {user.team_id}
        return {EVERY_TEAM}
    if isinstance(row, Task):
        return {row.team_id}
    if isinstance(row, Team):
        return {row.id}
    if isinstance(row, World):
        return {EVERY_TEAM}
    if isinstance(row, TeamInstance) and row.team_id:
        # assigned to a team; not its own health or sync records, which would loop
        return {row.team_id} if inspect(row).attrs.team_id.history.has_changes() else set()
    return set()


@event.listens_for(Session, "after_flush")
def _note_changes(session: Session, _context: object) -> None:
    teams: set[int] = session.info.setdefault(DIRTY, set())
    changed = [row for row in session.dirty if not isinstance(row, User) or _user_synced(row)]
    for row in session.new:
        teams |= _teams_of(row, created=True)
    for row in (*changed, *session.deleted):
        teams |= _teams_of(row)
        if isinstance(row, User):  # moved out of a team: the old one's instance too
            old: list[int | None] = list(inspect(row).attrs.team_id.history.deleted or ())
            teams |= {t for t in old if t}


@event.listens_for(Session, "before_commit")
def _start_syncs(session: Session) -> None:
    session.flush()  # the commit would flush after this hook: note its changes first
    teams = session.info.pop(DIRTY, None)
    if not teams:
        return
    # the two columns it needs only: this runs on every commit that touches a team or a user
    query = select(TeamInstance.id, TeamInstance.team_id).where(
        TeamInstance.state == InstanceState.READY
    )
    if EVERY_TEAM not in teams:
        query = query.where(TeamInstance.team_id.in_(teams))
    # One job per change, never folded into a queued one: a queued job may already have read
    # the database when this commit lands (the periodic reconcile would catch up, but later).
    for instance_id, team_id in session.execute(query).all():
        enqueue(SYNC_JOB, SYSTEM, InstanceJob(instance_id), team_id=team_id)
    session.info.pop(DIRTY, None)  # the jobs' own rows concern nobody


@event.listens_for(Session, "after_rollback")
def _forget_changes(session: Session) -> None:
    session.info.pop(DIRTY, None)
