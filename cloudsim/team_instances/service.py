"""Deploy, assign, look at and terminate team instances (admins only, for every caller)."""

from __future__ import annotations

from typing import Any

from sqlalchemy import Select, select
from sqlalchemy.orm import selectinload

from cloudsim.api.common import columns
from cloudsim.audit.service import record
from cloudsim.auth.policy import Actor, require_role
from cloudsim.errors import Conflict, InvalidInput, NotFound
from cloudsim.extensions import db
from cloudsim.jobs.control import cancel_jobs
from cloudsim.jobs.progress import job_step
from cloudsim.launched_constellations import service as constellations
from cloudsim.models import AuditEvent, InstanceState, Job, Role, Team, TeamInstance
from cloudsim.models.lookup import by_id_or_name
from cloudsim.team_instances import lifecycle

KIND = "cloudsim"  # the constellation kind that runs a CloudSim
MAX_SPARES = 50
LIVE = (InstanceState.DEPLOYING, InstanceState.READY, InstanceState.UNREACHABLE)


def visible_instances(actor: Actor) -> Select[TeamInstance]:
    """Return a query for every team instance, newest first (admins)."""
    require_role(actor, Role.ADMIN, "see team instances")
    return (
        select(TeamInstance)
        .options(selectinload(TeamInstance.team), selectinload(TeamInstance.constellation))
        .order_by(TeamInstance.id.desc())
    )


def get_instance(actor: Actor, ref: int | str) -> TeamInstance:
    """Return a team instance by id or name (admins)."""
    require_role(actor, Role.ADMIN, "see team instances")
    instance = by_id_or_name(TeamInstance, ref, InstanceState.TERMINATED)
    if instance is None:
        raise NotFound.of("team instance", ref)
    return instance


def latest_job(instance: TeamInstance) -> Job | None:
    """Return the instance's most recent job: its own (sync, launch through it) or its
    constellation's (deploy, terminate)."""
    return db.session.scalar(
        select(Job)
        .where(
            ((Job.target_type == "team_instance") & (Job.target_id == instance.id))
            | ((Job.target_type == "constellation") & (Job.target_id == instance.constellation_id))
        )
        .order_by(Job.created_at.desc())
        .limit(1)
    )


def status(actor: Actor, ref: int | str) -> dict[str, Any]:
    """Return a team instance's columns and its latest job's step and since when (admins)."""
    instance = get_instance(actor, ref)
    return {**columns(instance), **job_step(latest_job(instance))}


def drift_history(actor: Actor, instance: TeamInstance, limit: int = 20) -> list[AuditEvent]:
    """Return the latest drift put back on the instance, newest first (admins)."""
    require_role(actor, Role.ADMIN, "see team instances")
    return list(
        db.session.scalars(
            select(AuditEvent)
            .where(
                AuditEvent.action == "team_instance.drift",
                AuditEvent.target_type == "team_instance",
                AuditEvent.target_id == str(instance.id),
            )
            .order_by(AuditEvent.id.desc())
            .limit(limit)
        )
    )


def _team(team_id: int | None) -> Team | None:
    if team_id is None:
        return None
    team = db.session.get(Team, team_id)
    if team is None:
        raise NotFound.of("team", team_id)
    live = db.session.scalar(
        select(TeamInstance.name).where(
            TeamInstance.team_id == team_id, TeamInstance.state.in_(LIVE)
        )
    )
    if live is not None:
        raise Conflict(f"{team.name} already has a team instance ({live})")
    return team


def deploy(
    actor: Actor, *, name: str, provider: str, team_id: int | None = None, count: int = 1
) -> list[tuple[TeamInstance, Job]]:
    """Deploy a CloudSim for a team, or `count` spares (no team yet) named NAME-1..N (admins)."""
    require_role(actor, Role.ADMIN, "deploy team instances")
    if not 1 <= count <= MAX_SPARES:
        raise InvalidInput(f"count must be 1 to {MAX_SPARES}")
    if count > 1 and team_id is not None:
        raise InvalidInput("several instances at once are spares: give no team, assign them later")
    team = _team(team_id)
    names = [name] if count == 1 else [f"{name.strip()}-{n}" for n in range(1, count + 1)]
    deployed = []
    for each in names:
        # The constellation is the master's machinery: no team sees it in its list.
        constellation, job = constellations.launch(actor, name=each, kind=KIND, provider=provider)
        instance = TeamInstance(name=constellation.name, team=team, constellation=constellation)
        lifecycle.deploying(instance)
        db.session.add(instance)
        db.session.flush()
        record(
            "team_instance.deploy",
            actor,
            target_type="team_instance",
            target_id=instance.id,
            team_id=team_id,
            name=instance.name,
            provider=provider,
        )
        deployed.append((instance, job))
    return deployed


def assign(actor: Actor, ref: int | str, team_id: int) -> TeamInstance:
    """Give a spare instance to a team (admins)."""
    instance = get_instance(actor, ref)
    if instance.state not in LIVE:
        raise Conflict(f"{instance.name} is {instance.state.value}")
    if instance.team_id == team_id:
        return instance
    if instance.team_id is not None:
        raise Conflict(f"{instance.name} already serves {instance.team.name}")  # type: ignore[union-attr]
    instance.team = _team(team_id)
    db.session.flush()
    record(
        "team_instance.assign",
        actor,
        target_type="team_instance",
        target_id=instance.id,
        team_id=team_id,
    )
    return instance


def terminate(actor: Actor, ref: int | str) -> Job:
    """Terminate an instance's machines (admins); its row stays, as history."""
    instance = get_instance(actor, ref)
    if instance.state == InstanceState.TERMINATED:
        raise Conflict(f"{instance.name} is already terminated")
    job = constellations.terminate(actor, instance.constellation_id)
    # a launch through the instance stops at its next step (the constellation's own jobs
    # were told by the terminate above)
    cancel_jobs("team_instance", instance.id, f"{instance.name} is being terminated")
    lifecycle.terminated(instance)
    record(
        "team_instance.terminate",
        actor,
        target_type="team_instance",
        target_id=instance.id,
        team_id=instance.team_id,
    )
    return job
