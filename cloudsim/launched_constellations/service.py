"""Launch, terminate and look at constellations; every rule checked here for every caller."""

from __future__ import annotations

import io
import re
import zipfile

from flask import current_app
from sqlalchemy import Select, select
from sqlalchemy.orm import selectinload

from cloudsim.audit.service import record
from cloudsim.auth.policy import Actor, require_role, require_team_access
from cloudsim.errors import Conflict, InvalidInput, NotFound
from cloudsim.extensions import db
from cloudsim.launched_constellations import lifecycle
from cloudsim.launched_constellations.access import TEAM_KINDS, refresh_team_access
from cloudsim.launched_constellations.capacity import require_room
from cloudsim.launched_constellations.keys import (
    constellation_keypair,
    instance_admin_password,
    stored_instance_ca,
)
from cloudsim.models import Constellation, ConstellationState, Job, Machine, Role, Team
from cloudsim.models.lookup import by_id_or_name
from cloudsim.providers.service import PROVIDERS
from constellations.definition import (
    ConstellationKind,
    DefinitionError,
    kind_data,
    load_kind,
    parse_kind,
)
from constellations.plans import PLANS
from constellations.plans.roles import CLOUDSIM_ADMIN_EMAIL, CLOUDSIM_PORT

NAME = re.compile(r"[a-z0-9]([a-z0-9-]{0,22}[a-z0-9])?\Z")
BUSY = (ConstellationState.PENDING, ConstellationState.LAUNCHING, ConstellationState.TERMINATING)


def visible_constellations(actor: Actor) -> Select[Constellation]:
    """Return a query for the constellations the actor may see, newest first."""
    query = (
        select(Constellation)
        .options(selectinload(Constellation.machines), selectinload(Constellation.team))
        .order_by(Constellation.id.desc())
    )
    if actor is not None and not actor.has_role(Role.OFFICER):
        query = query.where(
            Constellation.team_id == actor.team_id, Constellation.team_id.is_not(None)
        )
    return query


def get_constellation(actor: Actor, ref: int | str) -> Constellation:
    """Return a constellation by id or name, if the actor may see it."""
    # the live one of that name, else the latest terminated one (history)
    constellation = by_id_or_name(Constellation, ref, ConstellationState.TERMINATED)
    if constellation is None:
        raise NotFound.of("constellation", ref)
    require_team_access(actor, constellation.team_id, "constellation", ref)
    return constellation


def latest_job(constellation: Constellation) -> Job | None:
    """Return the constellation's most recent job."""
    return db.session.scalar(
        select(Job)
        .where(Job.target_type == "constellation", Job.target_id == constellation.id)
        .order_by(Job.created_at.desc())
        .limit(1)
    )


def launch(
    actor: Actor, *, name: str, kind: str, provider: str, team_id: int | None = None
) -> tuple[Constellation, Job]:
    """Record a new constellation and start the job that launches it (admins)."""
    require_role(actor, Role.ADMIN, "launch constellations")
    name = name.strip().lower()
    if not NAME.match(name):
        raise InvalidInput(
            "constellation name must be 1-24 lowercase letters, digits or '-', "
            "not starting or ending with '-'"
        )
    try:
        data = kind_data(kind)
        definition = parse_kind(data, set(PLANS))
    except DefinitionError as exc:
        raise InvalidInput(str(exc)) from None
    if provider not in PROVIDERS:
        raise InvalidInput(f"unknown provider {provider!r}; known: {', '.join(PROVIDERS)}")
    if team_id is not None and db.session.get(Team, team_id) is None:
        raise NotFound.of("team", team_id)
    live = select(Constellation.id).where(
        Constellation.name == name, Constellation.state != ConstellationState.TERMINATED
    )
    if db.session.scalar(live):
        raise Conflict(f"a constellation named {name!r} already exists")
    require_room(provider, definition, current_app.config["CLOUDSIM"])
    constellation = Constellation(
        name=name,
        kind=kind,
        definition=data,
        provider=provider,
        team_id=team_id,
        created_by_id=actor.id if actor else None,
    )
    for machine in definition.machines:
        constellation.machines.append(
            Machine(name=machine.name, role=machine.role, size=machine.size)
        )
    db.session.add(constellation)
    db.session.flush()
    record(
        "constellation.launch",
        actor,
        target_type="constellation",
        target_id=constellation.id,
        team_id=team_id,
        name=name,
        kind=kind,
        provider=provider,
    )
    return constellation, lifecycle.start_launch(actor, constellation)


def retry(actor: Actor, ref: int | str) -> Job:
    """Launch again a constellation that ended in error (resuming what exists), or terminate
    again one whose terminate left a machine not cleaned."""
    require_role(actor, Role.ADMIN, "retry launches")
    constellation = get_constellation(actor, ref)
    if constellation.state == ConstellationState.TERMINATE_INCOMPLETE:
        return terminate(actor, ref)
    if constellation.state != ConstellationState.ERROR:
        raise Conflict(f"{constellation.name} is {constellation.state.value}, not in error")
    _audit("constellation.retry", actor, constellation)
    return lifecycle.retry(actor, constellation)


def terminate(actor: Actor, ref: int | str) -> Job:
    """Start releasing every resource of a constellation (admins); safe to repeat."""
    require_role(actor, Role.ADMIN, "terminate constellations")
    constellation = get_constellation(actor, ref)
    if constellation.state == ConstellationState.TERMINATED:
        raise Conflict(f"{constellation.name} is already terminated")
    running = latest_job(constellation)
    if (
        running is not None
        and running.kind == "constellation.terminate"
        and not running.state.final
    ):
        return running
    _audit("constellation.terminate", actor, constellation)
    return lifecycle.start_terminate(actor, constellation)


def _audit(action: str, actor: Actor, constellation: Constellation) -> None:
    """Record an action on a constellation in the audit log."""
    record(
        action,
        actor,
        target_type="constellation",
        target_id=constellation.id,
        team_id=constellation.team_id,
    )


def set_team_sudo(actor: Actor, ref: int | str, allowed: bool) -> Constellation:
    """Let the team's members on the field computers use sudo, or not (officers); pushed at once."""
    require_role(actor, Role.OFFICER, "change what a team may do on its field computers")
    constellation = get_constellation(actor, ref)
    if constellation.kind not in TEAM_KINDS:
        raise InvalidInput(
            f"{constellation.name} is a {constellation.kind} constellation: "
            "it has no field computers for the team's members"
        )
    if constellation.team_sudo != allowed:
        constellation.team_sudo = allowed
        record(
            "constellation.team_sudo",
            actor,
            target_type="constellation",
            target_id=constellation.id,
            team_id=constellation.team_id,
            allowed=allowed,
        )
        db.session.flush()
        if constellation.state == ConstellationState.READY:
            refresh_team_access([], also=[constellation])
    return constellation


def ssh_bundle(actor: Actor, ref: int | str) -> tuple[str, bytes]:
    """Return (file name, zip) with the constellation's SSH key and how to use it (officers)."""
    require_role(actor, Role.OFFICER, "download SSH keys")
    constellation = get_constellation(actor, ref)
    if constellation.state == ConstellationState.TERMINATED:
        raise Conflict(f"{constellation.name} is terminated; its keys are gone")
    keys = constellation_keypair(constellation)
    lines = [f"SSH access to constellation {constellation.name} ({constellation.kind})", ""]
    for machine in constellation.machines:
        address = machine.public_ip or machine.private_ip or "(not created yet)"
        lines.append(f"  {machine.name:8} {machine.role:8} {address}")
    lines += [
        "",
        f"ssh -i {constellation.name}.key root@ADDRESS",
        "Machines without a public address are reached through the router "
        f"(ssh -J root@ROUTER -i {constellation.name}.key root@ADDRESS).",
    ]
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as bundle:
        key_info = zipfile.ZipInfo(f"{constellation.name}.key")
        key_info.external_attr = 0o600 << 16
        bundle.writestr(key_info, keys.private)
        bundle.writestr(f"{constellation.name}.key.pub", keys.public + "\n")
        bundle.writestr("README.txt", "\n".join(lines) + "\n")
        if constellation.kind == "cloudsim":
            server = next((m for m in constellation.machines if m.public_ip), None)
            url = f"https://{server.public_ip}:{CLOUDSIM_PORT}/" if server else "(not created yet)"
            ca = stored_instance_ca(constellation)
            bundle.writestr(
                "cloudsim-admin.txt",
                (
                    f"CloudSim of {constellation.name}: {url}\n"
                    f"admin: {CLOUDSIM_ADMIN_EMAIL}\n"
                    f"password: {instance_admin_password(constellation)}\n"
                    + (
                        "its certificate is signed by cloudsim-ca.crt (trust that CA)\n"
                        if ca
                        else ""
                    )
                ),
            )
            if ca:
                bundle.writestr("cloudsim-ca.crt", ca)
    _audit("constellation.ssh_bundle", actor, constellation)
    return f"{constellation.name}-ssh.zip", buffer.getvalue()


def launched_kind(constellation: Constellation) -> ConstellationKind:
    """Return the kind the constellation was launched as (stored at launch; rows from before
    that was stored are read from the kind's file)."""
    if constellation.definition is not None:
        return parse_kind(constellation.definition, set(PLANS))
    return load_kind(constellation.kind, set(PLANS))
