"""Who may log into a team's field computers: each member's own account and keys, sudo, and
the refresh that pushes them."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from contextlib import contextmanager

import redis
from flask import current_app
from redis.exceptions import LockError
from sqlalchemy import select

from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.launched_constellations import lifecycle
from cloudsim.models import Constellation, ConstellationState, Role, SshKey, User
from constellations.plans.base import MemberAccount, member_account_name
from provisioners.remote.operations import MachineTemplates

TEAM_KINDS = ("vrc",)  # kinds whose field computers have the members' accounts
ACCOUNT_PLACEHOLDER = "YOUR_ACCOUNT"  # in the ssh_config of someone with no account there
REFRESH_LOCK_SECONDS = 600  # longest a refresh waits for the one before it (and holds it)


class RefreshBusy(CloudSimError):
    """Another refresh of the constellation's access held its lock for too long."""


@contextmanager
def refresh_turn(constellation_id: int) -> Iterator[None]:
    """Let one refresh of a constellation's access run at a time.

    Two at once would race on the machines: one that read the members before a member was
    disabled could write that member's account back after the other removed it. One after
    the other, each reads who the members are once it holds the lock, so the last one to
    run pushes the newest. The lock expires by itself if its holder dies.
    """
    config: Config = current_app.config["CLOUDSIM"]
    client = redis.Redis.from_url(config.effective_redis_url)
    lock = client.lock(
        f"cloudsim:constellation:{constellation_id}:access", timeout=REFRESH_LOCK_SECONDS
    )
    if not lock.acquire(blocking_timeout=REFRESH_LOCK_SECONDS):
        raise RefreshBusy(
            f"constellation {constellation_id}: another refresh of its access still runs "
            f"after {REFRESH_LOCK_SECONDS} s"
        )
    try:
        yield
    finally:
        try:
            lock.release()
        except LockError:
            pass  # expired: whoever took it since keeps it


def team_members(team_id: int | None) -> tuple[MemberAccount, ...]:
    """Return the account each active member of the team gets on its field computers."""
    if team_id is None:
        return ()
    members = db.session.execute(
        select(User.id, User.email)
        .where(User.team_id == team_id, User.active.is_(True), User.role == Role.USER)
        .order_by(User.id)
    ).all()
    keys: dict[int, list[str]] = {}
    for user_id, key, email in db.session.execute(
        select(SshKey.user_id, SshKey.public_key, User.email)
        .join(User, SshKey.user_id == User.id)
        .where(User.team_id == team_id)
        .order_by(SshKey.id)
    ):
        keys.setdefault(user_id, []).append(f"{key} {email}")
    return tuple(MemberAccount(uid, email, tuple(keys.get(uid, ()))) for uid, email in members)


def account_name(user: User | None, constellation: Constellation) -> str | None:
    """Return the user's account on the constellation's field computers, None if they have
    none (not an active member of its team)."""
    if (
        user is None
        or not user.active
        or user.role != Role.USER
        or constellation.team_id is None
        or user.team_id != constellation.team_id
    ):
        return None
    return member_account_name(user.email, user.id)


def refresh_team_access(team_ids: Iterable[int | None], also: Iterable[Constellation] = ()) -> None:
    """Push the current keys and VPN revocations to the teams' constellations (and `also`)."""
    wanted = {c.id: c for c in also}
    teams = {t for t in team_ids if t is not None}
    if teams:
        for constellation in db.session.scalars(
            select(Constellation).where(
                Constellation.team_id.in_(teams),
                Constellation.kind.in_(TEAM_KINDS),
                Constellation.state == ConstellationState.READY,
            )
        ):
            wanted[constellation.id] = constellation
    for constellation in wanted.values():
        lifecycle.start_refresh_access(SYSTEM, constellation)


def field_computers(constellation: Constellation) -> dict[str, str]:
    """Return the LAN address of each field computer (machine name -> address)."""
    return {m.name: m.private_ip or "?" for m in constellation.machines if m.role == "fc"}


def ssh_config(constellation: Constellation, user: User | None) -> str:
    """Return the ssh_config snippet that logs the user into the team's field computers as
    their own account (a placeholder for someone who has none there)."""
    return MachineTemplates().render(
        "router/team-ssh-config.j2",
        {
            "constellation": constellation.name,
            "field_computers": field_computers(constellation),
            "user": account_name(user, constellation) or ACCOUNT_PLACEHOLDER,
        },
    )
