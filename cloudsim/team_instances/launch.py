"""Constellations launched through team instances: the master hands an instance the provider
settings it keeps for it (encrypted, here and there), asks the instance to launch the team's
constellation (its own `POST /api/v1/constellations`, as its admin), and follows it.

The master records on each instance (`TeamInstance.launch`) what it last saw: the kind, the
provider, the instance's constellation and job ids once the instance took the launch, their
state, stage and progress (updated by every poll), and why it failed. A launch the instance
never took leaves the instance's constellation list as it was.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from flask import current_app
from sqlalchemy import select

from cloudsim.audit.service import record
from cloudsim.auth.policy import Actor, require_role
from cloudsim.errors import InvalidInput
from cloudsim.extensions import db
from cloudsim.jobs.runner import JobContext, Payload, job_kind
from cloudsim.jobs.service import enqueue
from cloudsim.models import InstanceState, Role, Secret, TeamInstance, utcnow
from cloudsim.providers.service import SETTINGS_PREFIX, configure_provider, stored_settings
from cloudsim.team_instances import service
from cloudsim.team_instances.client import Endpoint, InstanceError, call
from constellations.definition import DefinitionError, kind_data
from provisioners.providers.registry import PROVIDERS, provider

LAUNCH_JOB = "team_instance.launch"
OWNER = "team_instance"
# what the instance's constellation is in, as the master last saw it: still going, or done
GOING = {"starting", "pending", "launching"}
FAILED = {"failed", "error", "terminating", "terminated"}


def _stored(instance_id: int, name: str) -> Secret | None:
    return stored_settings(name, (OWNER, instance_id))


def set_provider_settings(
    actor: Actor, ref: int | str, name: str, settings: dict[str, Any]
) -> TeamInstance:
    """Keep (encrypted) the provider settings the master hands this instance at launch
    (admins); checked as `cloudsim provider configure` checks them."""
    instance = service.get_instance(actor, ref)
    configure_provider(name, settings, (OWNER, instance.id))
    # which provider, never what: the settings hold credentials
    record(
        "team_instance.provider",
        actor,
        target_type="team_instance",
        target_id=instance.id,
        team_id=instance.team_id,
        provider=name,
    )
    return instance


def kept_settings(instance_id: int) -> dict[str, datetime]:
    """Return which providers' settings are kept for an instance, and when each was set."""
    rows = db.session.execute(
        select(Secret.name, Secret.created_at).where(
            Secret.owner_type == OWNER,
            Secret.owner_id == instance_id,
            Secret.name.startswith(SETTINGS_PREFIX),
        )
    )
    return {name.removeprefix(SETTINGS_PREFIX): when for name, when in rows}


@dataclass(frozen=True)
class Outcome:
    """One instance's line in a launch's summary."""

    instance_id: int
    instance: str
    team: str | None
    state: str  # ready, launching or failed
    why: str | None = None
    job_id: str | None = None


def outcome(instance: TeamInstance, job_id: str | None = None) -> Outcome:
    """Summarise where an instance's launch is, from what the master last saw."""
    launch = instance.launch or {}
    state = launch.get("state")
    team = _team(instance)
    if state is None:
        return Outcome(instance.id, instance.name, team, "failed", "not launched", job_id)
    if state == "ready":
        return Outcome(instance.id, instance.name, team, "ready", job_id=job_id)
    if state in FAILED:
        why = launch.get("error") or f"its constellation is {state}"
        return Outcome(instance.id, instance.name, team, "failed", why, job_id)
    return Outcome(instance.id, instance.name, team, "launching", launch.get("stage"), job_id)


def _refusal(instance: TeamInstance, name: str) -> str | None:
    """Say why this instance cannot launch now, or None."""
    if instance.team is None:
        return "a spare: assign it to a team first"
    if instance.state != InstanceState.READY:
        return f"the instance is {instance.state.value}" + (
            f": {instance.error}" if instance.error else ""
        )
    if provider(name).configurable and _stored(instance.id, name) is None:
        return (
            f"no {name} settings for it: set them on its page or "
            f"`cloudsim instance provider {instance.name} {name} ...`"
        )
    return None


def launch(
    actor: Actor, kind: str, provider_name: str, refs: list[int | str] | None = None
) -> list[Outcome]:
    """Launch the team's constellation through each instance (every team's when refs is None;
    admins); return who is ready, launching, or failed and why. One already launched or
    launching is not launched again."""
    require_role(actor, Role.ADMIN, "launch constellations through team instances")
    try:
        kind_data(kind)
    except DefinitionError as exc:
        raise InvalidInput(str(exc)) from None
    if provider_name not in PROVIDERS:
        raise InvalidInput(f"unknown provider {provider_name!r}; known: {', '.join(PROVIDERS)}")
    if refs is None:
        query = service.visible_instances(actor).where(
            TeamInstance.state != InstanceState.TERMINATED, TeamInstance.team_id.is_not(None)
        )
        instances = sorted(db.session.scalars(query), key=lambda i: i.name)
    else:
        instances = [service.get_instance(actor, ref) for ref in refs]
    summary = []
    for instance in instances:
        launch_state = (instance.launch or {}).get("state")
        if launch_state is not None and launch_state not in FAILED:
            summary.append(outcome(instance))
            continue
        why = _refusal(instance, provider_name)
        if why is not None:
            summary.append(Outcome(instance.id, instance.name, _team(instance), "failed", why))
            continue
        payload = LaunchJob(instance.id, kind, provider_name)
        job = enqueue(LAUNCH_JOB, actor, payload, team_id=instance.team_id)
        instance.launch = {"kind": kind, "provider": provider_name, "state": "starting"}
        record(
            "team_instance.launch",
            actor,
            target_type="team_instance",
            target_id=instance.id,
            team_id=instance.team_id,
            kind=kind,
            provider=provider_name,
        )
        summary.append(outcome(instance, job.id))
    db.session.flush()
    return summary


def _team(instance: TeamInstance) -> str | None:
    return instance.team.name if instance.team else None


@dataclass(frozen=True)
class LaunchJob(Payload):
    """The payload of a launch through an instance: which instance, what, where."""

    instance_id: int
    kind: str
    provider: str

    def about(self) -> tuple[str, int]:
        return ("team_instance", self.instance_id)


def _secrets_in(value: Any) -> list[str]:
    """Return the long strings in settings (keys, passwords), to mask in the job's log."""
    if isinstance(value, dict):
        return [s for v in value.values() for s in _secrets_in(v)]
    if isinstance(value, list):
        return [s for v in value for s in _secrets_in(v)]
    return [value] if isinstance(value, str) and len(value) >= 16 else []


def _take(endpoint: Endpoint, payload: LaunchJob, team: str) -> dict[str, Any]:
    """Have the instance launch the team's constellation (or find the one it launched)."""
    teams = call(endpoint, "GET", "/teams?page_size=500")
    team_id = next((t["id"] for t in teams if t["name"] == team), None)
    if team_id is None:
        raise InstanceError(f"{team} is not on the instance yet: its first sync has not run")
    name = payload.kind  # one team per instance: the kind names its constellation there
    for existing in call(endpoint, "GET", "/constellations?page_size=500"):
        if existing["name"] != name or existing["state"] == "terminated":
            continue
        if existing["state"] == "error":  # launched before and failed: resume it there
            job = call(endpoint, "POST", f"/constellations/{existing['id']}/retry", timeout=30)
            return {"constellation": {**existing, "state": "launching"}, "job": job}
        if existing["state"] == "terminating":
            raise InstanceError(f"its {name} is terminating: launch again once it is gone")
        return {"constellation": existing, "job": None}  # a retried job: taken already
    body = {"name": name, "kind": payload.kind, "provider": payload.provider, "team_id": team_id}
    return call(endpoint, "POST", "/constellations", body, timeout=30)  # type: ignore[no-any-return]


@job_kind(LAUNCH_JOB, payload=LaunchJob)
def launch_through_instance(ctx: JobContext, payload: LaunchJob) -> None:
    """Hand the instance its provider settings, then have it launch the team's constellation."""
    from cloudsim.team_instances.poll import endpoint_of

    instance = ctx.load(TeamInstance, payload.instance_id)
    launch = {"kind": payload.kind, "provider": payload.provider, "state": "starting"}
    try:
        if instance.team is None or instance.state != InstanceState.READY:
            raise InstanceError(f"{instance.name} is {instance.state.value} or has no team")
        endpoint = endpoint_of(instance, current_app.config["CLOUDSIM"])
        ctx.mask(endpoint.token)
        secret = _stored(instance.id, payload.provider)
        if secret is not None:
            settings = json.loads(secret.value)
            ctx.mask(*_secrets_in(settings))
            ctx.stage("handing the instance its provider settings", 10)
            call(endpoint, "PUT", f"/providers/{payload.provider}", {"settings": settings})
        ctx.stage("asking the instance to launch", 50)
        taken = _take(endpoint, payload, instance.team.name)
    except InstanceError as exc:
        instance.launch = {**launch, "state": "failed", "error": str(exc), "seen_at": _now()}
        ctx.checkpoint()
        raise
    remote = taken["constellation"]
    instance.launch = {
        **launch,
        "state": remote["state"],
        "constellation_id": remote["id"],
        "job_id": (taken.get("job") or {}).get("id"),
        "error": remote.get("error"),
        "seen_at": _now(),
    }
    ctx.log(f"{instance.name} launches its constellation {remote['name']} (id {remote['id']})")
    ctx.checkpoint()  # not when the instance was terminated meanwhile: it is cancelled then


def _now() -> str:
    return utcnow().isoformat()


def follow(endpoint: Endpoint, launch: dict[str, Any], timeout: float) -> dict[str, Any] | str:
    """Read the launched constellation's state and its job's progress from the instance."""
    try:
        remote = call(
            endpoint, "GET", f"/constellations/{launch['constellation_id']}", timeout=timeout
        )
        job = None
        if launch.get("job_id") and remote["state"] in GOING:
            job = call(endpoint, "GET", f"/jobs/{launch['job_id']}", timeout=timeout)
    except InstanceError as exc:
        return str(exc)
    seen = {"state": remote["state"], "error": remote.get("error"), "seen_at": _now()}
    if job is not None:
        seen.update(stage=job.get("stage"), progress=job.get("progress"))
    elif remote["state"] == "ready":
        seen.update(stage=None, progress=100)
    return seen


def followed(instance: TeamInstance, seen: dict[str, Any] | str | None) -> None:
    """Record what a poll saw of the instance's constellation (or why it could not look)."""
    if seen is None or instance.launch is None:
        return
    if isinstance(seen, str):
        instance.launch = {**instance.launch, "poll_error": seen}
    else:
        instance.launch = {**instance.launch, **seen, "poll_error": None}


def launch_of(instance: TeamInstance) -> dict[str, Any] | None:
    """Return what a poll should follow: the launch, once the instance took it."""
    launch = instance.launch
    return launch if launch and launch.get("constellation_id") else None
