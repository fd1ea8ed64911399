"""Create, change and remove teams and users; every rule is checked here, for every caller."""

from __future__ import annotations

import enum
from dataclasses import dataclass

from email_validator import EmailNotValidError, validate_email
from sqlalchemy import Select, func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import selectinload

from cloudsim.audit.service import record
from cloudsim.auth.master import refuse_for_master_account
from cloudsim.auth.passwords import generate_password, hash_password
from cloudsim.auth.policy import SYSTEM, Actor, require_role, require_team_access
from cloudsim.auth.session import end_sessions
from cloudsim.auth.tokens import revoke_all_tokens
from cloudsim.errors import Conflict, Forbidden, InvalidInput, NotFound
from cloudsim.extensions import db
from cloudsim.models import (
    Constellation,
    ConstellationState,
    Job,
    Role,
    Run,
    Team,
    TeamInstance,
    User,
)
from cloudsim.people.access import revoke_before_delete, revoke_team_access
from cloudsim.web.inputs import as_id

TEAM_NAME_MAX = 80


class Keep(enum.Enum):
    """Marks an argument left out of an update, where None would mean "clear it"."""

    KEEP = "keep"


def normalise_email(email: str) -> str:
    """Return the canonical, lower-case form of an e-mail address or raise InvalidInput."""
    try:
        return validate_email(email.strip(), check_deliverability=False).normalized.lower()
    except EmailNotValidError as exc:
        raise InvalidInput(f"invalid e-mail address: {exc}") from None


def parse_role(value: str | Role) -> Role:
    """Return the Role named by value or raise InvalidInput listing the valid ones."""
    try:
        return Role(value)
    except ValueError:
        names = ", ".join(r.value for r in Role)
        raise InvalidInput(f"unknown role {value!r}; choose one of {names}") from None


# Teams -----------------------------------------------------------------------------------


def get_team(actor: Actor, team_id: int) -> Team:
    """Return the team if it exists and the actor may see it."""
    require_team_access(actor, team_id, "team", team_id)
    team = db.session.get(Team, team_id)
    if team is None:
        raise NotFound.of("team", team_id)
    return team


def find_team(name_or_id: str) -> Team:
    """Return the team with this name or numeric id (for the CLI)."""
    team = db.session.scalar(select(Team).where(Team.name == name_or_id.strip()))
    if team is None and (team_id := as_id(name_or_id.strip())) is not None:
        team = db.session.get(Team, team_id)
    if team is None:
        raise NotFound(f"no team named {name_or_id!r}")
    return team


def visible_teams(actor: Actor) -> list[Team]:
    """Return the teams the actor may see, by name."""
    query = select(Team).order_by(Team.name)
    if not actor.has_role(Role.OFFICER):
        query = query.where(Team.id == actor.team_id)
    return list(db.session.scalars(query))


def member_counts(teams: list[Team]) -> dict[int, int]:
    """Return each team's number of members (every team listed, in one query)."""
    counted = db.session.execute(
        select(User.team_id, func.count(User.id))
        .where(User.team_id.in_([t.id for t in teams]))
        .group_by(User.team_id)
    )
    return {t.id: 0 for t in teams} | {team_id: n for team_id, n in counted if team_id}


def _clean_team_name(name: str) -> str:
    cleaned = " ".join(name.split())
    if not cleaned:
        raise InvalidInput("team name must not be empty")
    if len(cleaned) > TEAM_NAME_MAX:
        raise InvalidInput(f"team name must be at most {TEAM_NAME_MAX} characters")
    return cleaned


def _ensure_team_name_free(name: str, except_id: int | None = None) -> None:
    query = select(Team.id).where(func.lower(Team.name) == name.lower())
    if except_id is not None:
        query = query.where(Team.id != except_id)
    if db.session.scalar(query) is not None:
        raise Conflict(f"a team named {name!r} already exists")


def _flush_team_name(name: str) -> None:
    """Flush a team's new name; the database's unique index has the last word on duplicates
    (its case folding is not Python's for non-ASCII names)."""
    try:
        db.session.flush()
    except IntegrityError:  # the caller's rollback (every boundary has one) clears the session
        raise Conflict(f"a team named {name!r} already exists") from None


def create_team(actor: Actor, name: str) -> Team:
    """Create a team (officers and admins)."""
    require_role(actor, Role.OFFICER, "create teams")
    name = _clean_team_name(name)
    _ensure_team_name_free(name)
    team = Team(name=name)
    db.session.add(team)
    _flush_team_name(name)
    record("team.create", actor, target_type="team", target_id=team.id, team_id=team.id, name=name)
    db.session.flush()
    return team


def rename_team(actor: Actor, team_id: int, name: str) -> Team:
    """Rename a team (officers and admins)."""
    require_role(actor, Role.OFFICER, "rename teams")
    team = get_team(actor, team_id)
    name = _clean_team_name(name)
    _ensure_team_name_free(name, except_id=team.id)
    old, team.name = team.name, name
    _flush_team_name(name)
    record(
        "team.rename",
        actor,
        target_type="team",
        target_id=team.id,
        team_id=team.id,
        old=old,
        new=name,
    )
    db.session.flush()
    return team


def delete_team(actor: Actor, team_id: int) -> None:
    """Delete a team that has no members and no live constellation."""
    require_role(actor, Role.OFFICER, "delete teams")
    team = get_team(actor, team_id)
    if team.members:
        raise Conflict(f"team {team.name!r} still has {len(team.members)} member(s)")
    live = [c for c in team.constellations if c.state != ConstellationState.TERMINATED]
    if live:
        raise Conflict(f"team {team.name!r} still has constellation {live[0].name!r}")
    history = _team_history(team.id)
    if history:
        raise Conflict(
            f"team {team.name!r} has a history ({', '.join(history)}) that deleting it would "
            "lose: it stays, without members"
        )
    record("team.delete", actor, target_type="team", target_id=team.id, name=team.name)
    db.session.delete(team)
    db.session.flush()


def _team_history(team_id: int) -> list[str]:
    """Return what the team has done ("2 run(s)", ...): its runs, constellations, jobs."""
    counted = (
        ("run(s)", Run.team_id),
        ("constellation(s)", Constellation.team_id),
        ("team instance(s)", TeamInstance.team_id),
        ("job(s)", Job.team_id),
    )
    found = []
    for label, column in counted:
        count = db.session.scalar(select(func.count()).where(column == team_id)) or 0
        if count:
            found.append(f"{count} {label}")
    return found


# Users -----------------------------------------------------------------------------------


@dataclass
class NewUser:
    """A created user and, when CloudSim chose it, the password to hand over once."""

    user: User
    generated_password: str | None


def get_user(actor: Actor, user_id: int) -> User:
    """Return the user if it exists and the actor may see it (officers; or oneself)."""
    if not actor.has_role(Role.OFFICER) and actor.id != user_id:
        raise NotFound.of("user", user_id)
    user = db.session.get(User, user_id)
    if user is None:
        raise NotFound.of("user", user_id)
    return user


def find_user(email_or_id: str) -> User:
    """Return the user with this e-mail address or numeric id (for the CLI)."""
    text = email_or_id.strip()
    user = db.session.scalar(select(User).where(User.email == text.lower()))
    if user is None and (user_id := as_id(text)) is not None:
        user = db.session.get(User, user_id)
    if user is None:
        raise NotFound(f"no user {email_or_id!r}")
    return user


def visible_users(actor: Actor, team_id: int | None = None) -> list[User]:
    """Return the users the actor may see: officers all, users their own team's."""
    return list(db.session.scalars(users_query(actor, team_id)))


def users_query(actor: Actor, team_id: int | None = None) -> Select[User]:
    """Return a query for the users the actor may see, by e-mail."""
    query = select(User).order_by(User.email, User.id).options(selectinload(User.team))
    if not actor.has_role(Role.OFFICER):
        query = query.where(User.team_id == actor.team_id)
    if team_id is not None:
        query = query.where(User.team_id == team_id)
    return query


def _check_manage(actor: Actor, role: Role) -> None:
    """Officers manage team users; only admins create or change officers and admins."""
    require_role(actor, Role.OFFICER, "manage users")
    if role != Role.USER and not actor.has_role(Role.ADMIN):
        raise Forbidden("only admins may manage officers and admins")


def _team_for_role(role: Role, team_id: int | None) -> int | None:
    if role == Role.USER:
        if team_id is None:
            raise InvalidInput("a user of role 'user' must belong to a team")
        if db.session.get(Team, team_id) is None:
            raise NotFound.of("team", team_id)
        return team_id
    if team_id is not None:
        raise InvalidInput(f"{role.value}s do not belong to a team; leave the team empty")
    return None


def create_user(
    actor: Actor,
    *,
    email: str,
    role: str | Role = Role.USER,
    team_id: int | None = None,
    name: str = "",
    password: str | None = None,
) -> NewUser:
    """Create a user; generate a password when none is given."""
    role = parse_role(role)
    _check_manage(actor, role)
    email = normalise_email(email)
    if db.session.scalar(select(User.id).where(User.email == email)) is not None:
        raise Conflict(f"a user with e-mail {email} already exists")
    team_id = _team_for_role(role, team_id)
    generated = None if password else generate_password()
    user = User(
        email=email,
        name=name.strip()[:120],
        role=role,
        team_id=team_id,
        password_hash=hash_password(password or generated or ""),
    )
    db.session.add(user)
    db.session.flush()
    record(
        "user.create",
        actor,
        target_type="user",
        target_id=user.id,
        team_id=team_id,
        email=email,
        role=role.value,
    )
    db.session.flush()
    return NewUser(user, generated)


def update_user(
    actor: Actor,
    user_id: int,
    *,
    name: str | None = None,
    role: str | Role | None = None,
    team_id: int | Keep | None = Keep.KEEP,
    active: bool | None = None,
    password: str | None = None,
) -> User:
    """Change a user's name, role, team, active flag or password."""
    user = get_user(actor, user_id)
    _check_manage(actor, user.role)
    new_role = parse_role(role) if role is not None else user.role
    if new_role != user.role or active is False or team_id not in (Keep.KEEP, user.team_id):
        refuse_for_master_account(user, "disabled, demoted or moved")
    _check_manage(actor, new_role)
    changes: dict[str, object] = {}
    old_team = user.team_id
    if actor.id == user.id and (new_role != user.role or active is False):
        raise Forbidden("you cannot change your own role or disable yourself")
    if new_role != user.role and user.role == Role.ADMIN:
        _ensure_another_admin(user)
    if role is not None or team_id is not Keep.KEEP:
        wanted_team = user.team_id if team_id is Keep.KEEP else team_id
        if new_role != Role.USER and team_id is Keep.KEEP:
            wanted_team = None  # promoting a team user to officer takes them out of the team
        user.team_id = _team_for_role(new_role, wanted_team)
        user.role = new_role
        # Not team_id=: that is record()'s own argument (the team the event belongs to).
        changes.update(role=new_role.value, team=user.team_id, old_team=old_team)
    access_changes = user.team_id != old_team or (active is not None and active != user.active)
    if name is not None:
        user.name = name.strip()[:120]
        changes["name"] = user.name
    if active is not None and active != user.active:
        if not active and user.role == Role.ADMIN:
            _ensure_another_admin(user)
        user.active = active
        if not active:  # a disabled account keeps no way in, even once enabled again
            end_sessions(user)
            revoke_all_tokens(user)
        changes["active"] = active
    if password:
        user.password_hash = hash_password(password)
        end_sessions(user)  # API tokens stay: they are revoked one by one, or by disabling
        changes["password"] = "changed"  # noqa: S105
    record(
        "user.update", actor, target_type="user", target_id=user.id, team_id=user.team_id, **changes
    )
    db.session.flush()
    if access_changes:
        # VPN certificates and SSH keys follow at once: off the old team, onto the new one
        revoke_team_access(user, old_team)
    return user


def delete_user(actor: Actor, user_id: int) -> None:
    """Delete a user (never oneself, never the last admin)."""
    user = get_user(actor, user_id)
    _check_manage(actor, user.role)
    refuse_for_master_account(user, "deleted")
    if actor.id == user.id:
        raise Forbidden("you cannot delete your own account")
    if user.role == Role.ADMIN:
        _ensure_another_admin(user)
    after_delete = revoke_before_delete(user)
    record(
        "user.delete",
        actor,
        target_type="user",
        target_id=user.id,
        team_id=user.team_id,
        email=user.email,
    )
    db.session.delete(user)
    db.session.flush()
    after_delete()  # jobs are sent once the caller commits: they see the user gone


def _ensure_another_admin(user: User) -> None:
    others = db.session.scalar(
        select(func.count(User.id)).where(
            User.role == Role.ADMIN, User.active.is_(True), User.id != user.id
        )
    )
    if not others:
        raise Conflict("CloudSim needs at least one active admin")


def ensure_first_admin(email: str, password: str | None) -> NewUser | None:
    """Create the first admin when no admin exists; return it (with its password if generated)."""
    if db.session.scalar(select(User.id).where(User.role == Role.ADMIN).limit(1)) is not None:
        return None
    return create_user(SYSTEM, email=email, role=Role.ADMIN, password=password, name="Admin")
