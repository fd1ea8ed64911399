"""Who may log into a team's field computers: the team account's keys, sudo, and the refresh."""

from __future__ import annotations

from collections.abc import Iterable

from sqlalchemy import select

from cloudsim.auth.policy import SYSTEM
from cloudsim.extensions import db
from cloudsim.launched_constellations import lifecycle
from cloudsim.models import Constellation, ConstellationState, Role, SshKey, User
from constellations.plans.roles import TEAM_USER
from provisioners.remote.operations import MachineTemplates

TEAM_KINDS = ("vrc",)  # kinds whose field computers have the team account


def team_keys(team_id: int | None) -> tuple[str, ...]:
    """Return the authorized_keys lines of the team's active members, each naming its owner."""
    if team_id is None:
        return ()
    rows = db.session.execute(
        select(SshKey.public_key, User.email)
        .join(User, SshKey.user_id == User.id)
        .where(User.team_id == team_id, User.active.is_(True), User.role == Role.USER)
        .order_by(SshKey.id)
    ).all()
    return tuple(f"{key} {email}" for key, email in rows)


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


def ssh_config(constellation: Constellation) -> str:
    """Return the ssh_config snippet that logs a member into the team's field computers."""
    return MachineTemplates().render(
        "router/team-ssh-config.j2",
        {
            "constellation": constellation.name,
            "field_computers": field_computers(constellation),
            "user": TEAM_USER,
        },
    )
