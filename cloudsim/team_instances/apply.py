"""On a team instance: make this CloudSim what its master says it must be (desired state).

Idempotent: every item is compared with what is here and only differences are changed, so a
repeated sync changes nothing. It also keeps (encrypted) how to upload finished runs to the
master's portal. The master's word is final for every account and every role: its team, the
users it lists (their role, team, name, active flag, password hash, SSH keys), the tasks it
made, and every world definition are put back when they were changed here by hand (drift);
every other active account, admins included, is disabled, except the master's own (the
caller). Tasks made here by hand are reported, not touched. The answer says what changed,
which of those changes were drift (see `drift.Seen`), and what was reported.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from drcsim.worlds import document_digest
from sqlalchemy import select

from cloudsim.auth.master import note_synced
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
from cloudsim.team_instances.drift import Seen
from cloudsim.worlds.service import checked, put_world, stored_worlds


@dataclass
class SyncResult:
    """What a sync changed here, and what it found but left for people to decide."""

    changed: list[str] = field(default_factory=list)
    reported: list[str] = field(default_factory=list)
    drift: list[str] = field(default_factory=list)  # the changes that put back a hand's work

    def put(self, change: str, drift: bool) -> None:
        """Note a change; `drift` when it undid a change made here (the master said the same)."""
        self.changed.append(change)
        if drift:
            self.drift.append(change)


def apply_desired_state(actor: Actor, desired: dict[str, Any]) -> SyncResult:
    """Apply a master's desired state (admins: the master's credential); return the changes."""
    require_role(actor, Role.ADMIN, "apply a master's desired state")
    if db.session.scalar(select(TeamInstance.id).limit(1)) is not None:
        # a master's own users are the source of truth: a desired state would disable them
        raise Conflict(
            "this CloudSim is a master (it has team instances): it takes no desired state"
        )
    result, seen = SyncResult(), Seen()
    team = _team(actor, desired.get("team"), result, seen)
    _users(actor, desired["users"], team, result, seen)
    if desired.get("worlds") is not None:  # before the tasks: they are checked against them
        _worlds(desired["worlds"], result, seen)
    _tasks(desired["tasks"], team, result, seen)
    if store_settings(desired.get("portal")):
        result.changed.append("portal upload settings updated")
    db.session.flush()
    seen.save()
    note_synced()  # logins open (after a start, they wait for this)
    return result


def _team(actor: Actor, name: str | None, result: SyncResult, seen: Seen) -> Team | None:
    for other in db.session.scalars(select(Team).where(Team.name != (name or ""))):
        result.reported.append(f"team {other.name!r} is not this instance's")
    if name is None:
        return None
    team = db.session.scalar(select(Team).where(Team.name == name))
    if team is not None:
        seen.same("team", name)
    else:
        team = create_team(actor, name)
        result.put(f"team {name!r} created", seen.same("team", name))
    return team


def _users(
    actor: Actor, wanted: list[dict[str, Any]], team: Team | None, result: SyncResult, seen: Seen
) -> None:
    listed = {spec["email"].strip().lower() for spec in wanted}
    for spec in wanted:
        _user(actor, spec, team, result, seen)
    # every other active account goes, admins too: only the master's own (the caller) stays
    others = select(User).where(User.active.is_(True), User.id != actor.id)
    for user in db.session.scalars(others):
        if user.email not in listed:
            update_user(actor, user.id, active=False)
            if seen.listed_before(f"user:{user.email}"):
                result.put(f"user {user.email} disabled (no longer listed by the master)", False)
            else:
                result.put(f"user {user.email} ({user.role.value}) disabled: made here", True)


def _user(
    actor: Actor, spec: dict[str, Any], team: Team | None, result: SyncResult, seen: Seen
) -> None:
    role = Role(spec["role"])
    team_id = team.id if role == Role.USER and team is not None else None
    email = spec["email"].strip().lower()
    drift = seen.same(f"user:{email}", spec)
    user = db.session.scalar(select(User).where(User.email == email))
    if user is not None and user.id == actor.id:
        result.reported.append(f"user {email} is the master's own account here: left alone")
        return
    if user is None:
        user = create_user(actor, email=email, role=role, team_id=team_id, name=spec["name"]).user
        result.put(f"user {email} created", drift)
    changes: dict[str, Any] = {}
    if user.name != spec["name"]:
        changes["name"] = spec["name"]
    if user.role != role or user.team_id != team_id:
        changes.update(role=role, team_id=team_id)
    if user.active != spec["active"]:
        changes["active"] = spec["active"]
    if changes:
        update_user(actor, user.id, **changes)
        result.put(f"user {email}: {', '.join(sorted(changes))}", drift)
    if user.password_hash != spec["password_hash"]:
        user.password_hash = spec["password_hash"]
        end_sessions(user)  # as a password change here would
        result.put(f"user {email}: password", drift)
    _keys(user, spec["ssh_keys"], result, drift)


def _keys(user: User, wanted: list[dict[str, str]], result: SyncResult, drift: bool) -> None:
    have = {key.public_key: key for key in user.ssh_keys}
    keep = {spec["public_key"] for spec in wanted}
    for public_key, key in have.items():
        if public_key not in keep:
            delete_key(user, key.id)
            result.put(f"user {user.email}: SSH key {key.fingerprint} removed", drift)
    for spec in wanted:
        if spec["public_key"] not in have:
            key = add_key(user, spec["public_key"], spec["name"])
            result.put(f"user {user.email}: SSH key {key.fingerprint} added", drift)


def _worlds(wanted: list[dict[str, Any]], result: SyncResult, seen: Seen) -> None:
    for spec in wanted:
        document = checked(spec["document"])  # the simulator here must be able to load it
        if document["name"] != spec["name"] or document_digest(document) != spec["digest"]:
            raise InvalidInput(f"world {spec['name']!r}: the document does not match its digest")
        drift = seen.same(f"world:{spec['name']}", [spec["version"], spec["digest"]])
        if put_world(spec["name"], spec["version"], document):
            result.put(f"world {spec['name']}: version {spec['version']}", drift)
    listed = {spec["name"] for spec in wanted}
    for world in stored_worlds():
        if world.name not in listed:
            result.reported.append(f"world {world.name} is not the master's")
    db.session.flush()


def _tasks(wanted: list[dict[str, Any]], team: Team | None, result: SyncResult, seen: Seen) -> None:
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
            result.put(f"task {task.name!r} removed", False)
    if team is None:
        if wanted:
            result.reported.append("tasks listed for an instance without a team: ignored")
        return
    for spec in wanted:
        values = _task_values(spec)
        drift = seen.same(f"task:{spec['key']}", spec)
        existing = here.get(spec["key"])
        if existing is None:
            db.session.add(Task(team_id=team.id, master_key=spec["key"], **values))
            result.put(f"task {values['name']!r} added", drift)
            continue
        differ = sorted(k for k, v in values.items() if getattr(existing, k) != v)
        if existing.team_id != team.id:
            existing.team_id = team.id
            differ.append("team")
        for name in differ:
            if name != "team":
                setattr(existing, name, values[name])
        if differ:
            result.put(f"task {values['name']!r}: {', '.join(differ)}", drift)


def _task_values(spec: dict[str, Any]) -> dict[str, Any]:
    """Return a task's columns from the master's spec, checked as a task scheduled here is."""
    checked = check_spec(TaskSpec(**{name: spec[name] for name in SPEC_FIELDS}))
    return {name: getattr(checked, name) for name in SPEC_FIELDS}
