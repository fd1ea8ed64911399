"""On a team instance: make this CloudSim what its master says it must be (desired state).

Idempotent: every item is compared with what is here and only differences are changed, so a
repeated sync changes nothing. It also keeps (encrypted) how to upload finished runs to the
master's portal. What the master manages is put back when it was changed here
by hand (drift): its team, the users it lists (their role, team, name, active flag, password
hash, SSH keys), the tasks it made, and every world definition (a world changed here by hand
is put back to the master's document and version). Users it does not list (other than
admins: its own credential and any local admin) are disabled; tasks made here by hand are
reported, not touched. The answer says what changed and what was reported.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from drcsim.worlds import document_digest
from sqlalchemy import select

from cloudsim.auth.policy import Actor, require_role
from cloudsim.auth.session import end_sessions
from cloudsim.auth.ssh_keys import add_key, delete_key
from cloudsim.competition.schedule import TaskSpec, check_spec
from cloudsim.competition.season import SPEC_FIELDS
from cloudsim.errors import Conflict, InvalidInput
from cloudsim.extensions import db
from cloudsim.models import Role, Task, Team, TeamInstance, User
from cloudsim.people.service import create_team, create_user, update_user
from cloudsim.portal.credentials import store_settings
from cloudsim.worlds.service import checked, put_world, stored_worlds


@dataclass
class SyncResult:
    """What a sync changed here, and what it found but left for people to decide."""

    changed: list[str] = field(default_factory=list)
    reported: list[str] = field(default_factory=list)


def apply_desired_state(actor: Actor, desired: dict[str, Any]) -> SyncResult:
    """Apply a master's desired state (admins: the master's credential); return the changes."""
    require_role(actor, Role.ADMIN, "apply a master's desired state")
    if db.session.scalar(select(TeamInstance.id).limit(1)) is not None:
        # a master's own users are the source of truth: a desired state would disable them
        raise Conflict(
            "this CloudSim is a master (it has team instances): it takes no desired state"
        )
    result = SyncResult()
    team = _team(actor, desired.get("team"), result)
    _users(actor, desired["users"], team, result)
    if desired.get("worlds") is not None:  # before the tasks: they are checked against them
        _worlds(desired["worlds"], result)
    _tasks(desired["tasks"], team, result)
    if store_settings(desired.get("portal")):
        result.changed.append("portal upload settings updated")
    db.session.flush()
    return result


def _team(actor: Actor, name: str | None, result: SyncResult) -> Team | None:
    for other in db.session.scalars(select(Team).where(Team.name != (name or ""))):
        result.reported.append(f"team {other.name!r} is not this instance's")
    if name is None:
        return None
    team = db.session.scalar(select(Team).where(Team.name == name))
    if team is None:
        team = create_team(actor, name)
        result.changed.append(f"team {name!r} created")
    return team


def _users(
    actor: Actor, wanted: list[dict[str, Any]], team: Team | None, result: SyncResult
) -> None:
    listed = {spec["email"].strip().lower() for spec in wanted}
    for spec in wanted:
        _user(actor, spec, team, result)
    others = select(User).where(User.role != Role.ADMIN, User.active.is_(True))
    for user in db.session.scalars(others):
        if user.email not in listed:
            update_user(actor, user.id, active=False)
            result.changed.append(f"user {user.email} disabled (not listed by the master)")


def _user(actor: Actor, spec: dict[str, Any], team: Team | None, result: SyncResult) -> None:
    role = Role(spec["role"])
    team_id = team.id if role == Role.USER and team is not None else None
    email = spec["email"].strip().lower()
    user = db.session.scalar(select(User).where(User.email == email))
    if user is None:
        user = create_user(actor, email=email, role=role, team_id=team_id, name=spec["name"]).user
        result.changed.append(f"user {email} created")
    elif user.role == Role.ADMIN:
        result.reported.append(f"user {email} is an admin here: left alone")
        return
    changes: dict[str, Any] = {}
    if user.name != spec["name"]:
        changes["name"] = spec["name"]
    if user.role != role or user.team_id != team_id:
        changes.update(role=role, team_id=team_id)
    if user.active != spec["active"]:
        changes["active"] = spec["active"]
    if changes:
        update_user(actor, user.id, **changes)
        result.changed.append(f"user {email}: {', '.join(sorted(changes))}")
    if user.password_hash != spec["password_hash"]:
        user.password_hash = spec["password_hash"]
        end_sessions(user)  # as a password change here would
        result.changed.append(f"user {email}: password")
    _keys(user, spec["ssh_keys"], result)


def _keys(user: User, wanted: list[dict[str, str]], result: SyncResult) -> None:
    have = {key.public_key: key for key in user.ssh_keys}
    keep = {spec["public_key"] for spec in wanted}
    for public_key, key in have.items():
        if public_key not in keep:
            delete_key(user, key.id)
            result.changed.append(f"user {user.email}: SSH key {key.fingerprint} removed")
    for spec in wanted:
        if spec["public_key"] not in have:
            key = add_key(user, spec["public_key"], spec["name"])
            result.changed.append(f"user {user.email}: SSH key {key.fingerprint} added")


def _worlds(wanted: list[dict[str, Any]], result: SyncResult) -> None:
    for spec in wanted:
        document = checked(spec["document"])  # the simulator here must be able to load it
        if document["name"] != spec["name"] or document_digest(document) != spec["digest"]:
            raise InvalidInput(f"world {spec['name']!r}: the document does not match its digest")
        if put_world(spec["name"], spec["version"], document):
            result.changed.append(f"world {spec['name']}: version {spec['version']}")
    listed = {spec["name"] for spec in wanted}
    for world in stored_worlds():
        if world.name not in listed:
            result.reported.append(f"world {world.name} is not the master's")
    db.session.flush()


def _tasks(wanted: list[dict[str, Any]], team: Team | None, result: SyncResult) -> None:
    here = {t.master_key: t for t in db.session.scalars(select(Task)) if t.master_key}
    for task in db.session.scalars(select(Task).where(Task.master_key.is_(None))):
        result.reported.append(f"task {task.name!r} ({task.id}) was made on this instance")
    keys = {spec["key"] for spec in wanted}
    for key, task in here.items():
        if key in keys:
            continue
        if task.runs:
            result.reported.append(f"task {task.name!r} is gone on the master but has runs here")
        else:
            db.session.delete(task)
            result.changed.append(f"task {task.name!r} removed")
    if team is None:
        if wanted:
            result.reported.append("tasks listed for an instance without a team: ignored")
        return
    for spec in wanted:
        values = _task_values(spec)
        existing = here.get(spec["key"])
        if existing is None:
            db.session.add(Task(team_id=team.id, master_key=spec["key"], **values))
            result.changed.append(f"task {values['name']!r} added")
            continue
        differ = sorted(k for k, v in values.items() if getattr(existing, k) != v)
        if existing.team_id != team.id:
            existing.team_id = team.id
            differ.append("team")
        for name in differ:
            if name != "team":
                setattr(existing, name, values[name])
        if differ:
            result.changed.append(f"task {values['name']!r}: {', '.join(differ)}")


def _task_values(spec: dict[str, Any]) -> dict[str, Any]:
    """Return a task's columns from the master's spec, checked as a task scheduled here is."""
    checked = check_spec(TaskSpec(**{name: spec[name] for name in SPEC_FIELDS}))
    return {name: getattr(checked, name) for name in SPEC_FIELDS}
