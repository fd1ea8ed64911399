"""The master's watch over its team instances, every CLOUDSIM_INSTANCE_POLL_SECONDS (beat)
or on demand (`cloudsim instance check`): each one's state and health, then its desired state
pushed again (the reconcile: drift made on the instance is put back, a lagging one caught up).

Network calls run in parallel with short timeouts, so one slow or dead instance never
holds up the others; the database is read before and written after, in this thread.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from datetime import timedelta
from typing import Any

import redis
from celery import shared_task
from flask import current_app
from sqlalchemy import select

from cloudsim.config import Config
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.launched_constellations.keys import instance_admin_token, instance_tls
from cloudsim.models import ConstellationState, InstanceState, TeamInstance
from cloudsim.providers.service import open_provider
from cloudsim.team_instances import lifecycle
from cloudsim.team_instances.client import Endpoint, InstanceError, call
from cloudsim.team_instances.launch import follow, followed, launch_of
from cloudsim.team_instances.sync import (
    desired_state,
    release,
    sync_failed,
    sync_lock,
    synced,
)
from constellations.plans.roles import CLOUDSIM_PORT

PARALLEL = 8
CALL_TIMEOUT = 10.0
CATCH_UP_TASK = "cloudsim.team_instances.catch_up"
CATCH_UP_EVERY = timedelta(seconds=1)
REFUSING_RECHECK = timedelta(seconds=10)
CATCH_UP_HEALTH_TIMEOUT = 1.0  # a lagging instance that does not answer this fast: next second


def endpoint_of(instance: TeamInstance, config: Config) -> Endpoint:
    """Return how to call an instance whose constellation is ready (pinning its certificate)."""
    constellation = instance.constellation
    address = next((m.public_ip for m in constellation.machines if m.public_ip), None)
    if address is None:
        raise InstanceError(f"{instance.name} has no public address")
    tls = instance_tls(constellation)
    if instance.cert_fingerprint is None:
        instance.cert_fingerprint = tls.fingerprint  # pinned from the first check on
    try:
        proxy = open_provider(constellation.provider, config).driver.ex_public_proxy_command(
            address, CLOUDSIM_PORT
        )
    except Exception as exc:  # a provider failing: unreachable
        raise InstanceError(f"no route to {address}: {exc}") from None
    return Endpoint(
        host=address,
        port=CLOUDSIM_PORT,
        ca_cert=tls.ca_cert,
        fingerprint=instance.cert_fingerprint,
        token=instance_admin_token(constellation),
        proxy=proxy,
    )


@dataclass(frozen=True)
class Visit:
    """What one instance answered: its health (or why not), the sync (or why not), and what
    it said of the constellation launched through it."""

    health: dict[str, Any] | str
    sync: dict[str, Any] | str | None = None
    launch: dict[str, Any] | str | None = None


def _visit(
    endpoint: Endpoint,
    desired: dict[str, Any],
    launch: dict[str, Any] | None,
    health_timeout: float = CALL_TIMEOUT,
) -> Visit:
    """Check an instance's health, push its desired state (the reconcile), then follow the
    constellation launched through it."""
    try:
        health = call(endpoint, "GET", "/instance/health", timeout=health_timeout)
    except InstanceError as exc:
        return Visit(str(exc))
    if not isinstance(health, dict):
        return Visit("the health check answered no object")
    seen = follow(endpoint, launch, CALL_TIMEOUT) if launch else None
    try:
        answer = call(endpoint, "PUT", "/instance/desired-state", desired, timeout=CALL_TIMEOUT)
    except InstanceError as exc:
        return Visit(health, str(exc), seen)
    sync = answer if isinstance(answer, dict) else "the sync answered no object"
    return Visit(health, sync, seen)


def check_instances(
    config: Config,
    ids: list[int] | None = None,
    connect: Callable[[TeamInstance, Config], Endpoint] = endpoint_of,
    health_timeout: float = CALL_TIMEOUT,
) -> list[TeamInstance]:
    """Bring every live instance's state up to date with its constellation and its health,
    and push its desired state. `connect` says how to reach one (bench/ uses stand-ins)."""
    query = select(TeamInstance).where(TeamInstance.state != InstanceState.TERMINATED)
    if ids is not None:
        query = query.where(TeamInstance.id.in_(ids))
    instances = list(db.session.scalars(query.order_by(TeamInstance.id)))
    endpoints: dict[int, Endpoint] = {}
    desired: dict[int, dict[str, Any]] = {}
    locks = []
    try:
        for instance in instances:
            state = instance.constellation.state
            if state == ConstellationState.ERROR:
                error = instance.constellation.error or "its constellation failed"
                lifecycle.failed(instance, error)
            elif state == ConstellationState.TERMINATED:
                lifecycle.terminated(instance)
            elif state == ConstellationState.READY:
                lock = sync_lock(instance.id)
                if not lock.acquire(blocking=False):
                    continue  # a sync job is at it: the next check looks again
                locks.append(lock)
                try:
                    endpoints[instance.id] = connect(instance, config)
                    desired[instance.id] = desired_state(instance)
                except (InstanceError, CloudSimError) as exc:
                    lifecycle.unreachable(instance, str(exc))
        with ThreadPoolExecutor(max_workers=PARALLEL) as pool:
            by_id = {i.id: i for i in instances}
            launches = [launch_of(by_id[i]) for i in endpoints]
            visits = pool.map(
                _visit,
                endpoints.values(),
                [desired[i] for i in endpoints],
                launches,
                [health_timeout] * len(endpoints),
            )
            answers = dict(zip(endpoints, visits, strict=True))
    finally:
        for lock in locks:
            release(lock)
    for instance in instances:
        visit = answers.get(instance.id)
        if visit is None:
            continue
        if isinstance(visit.health, str):
            lifecycle.unreachable(instance, visit.health)
            sync_failed(instance, f"unreachable: {visit.health}")
            continue
        lifecycle.healthy(instance, endpoints[instance.id].url, visit.health)
        followed(instance, visit.launch)
        if isinstance(visit.sync, dict):
            synced(instance, visit.sync)
        elif visit.sync is not None:
            sync_failed(instance, visit.sync)
    db.session.flush()
    return instances


def lagging_instances() -> list[int]:
    """Return the instances behind their master: unreachable, or whose last sync failed."""
    behind = (TeamInstance.state == InstanceState.UNREACHABLE) | (
        (TeamInstance.state == InstanceState.READY) & TeamInstance.sync_error.is_not(None)
    )
    return list(db.session.scalars(select(TeamInstance.id).where(behind)))


def _resting(instance_id: int) -> str:
    return f"cloudsim:team-instance:{instance_id}:catch-up-rest"


def catch_up(config: Config) -> list[TeamInstance]:
    """Check the lagging instances now: one that answers again gets its desired state at
    once, not at the next poll (beat, every second; a query when none lags). One that answers
    but refuses its sync rests REFUSING_RECHECK between tries, so it is not hammered."""
    client = redis.Redis.from_url(config.effective_redis_url, socket_timeout=5)
    ids = [i for i in lagging_instances() if not client.exists(_resting(i))]
    if not ids:
        return []
    checked = check_instances(config, ids, health_timeout=CATCH_UP_HEALTH_TIMEOUT)
    for instance in checked:
        if instance.state == InstanceState.READY and instance.sync_error:
            client.set(_resting(instance.id), "1", ex=REFUSING_RECHECK)
    return checked


@shared_task(name=CATCH_UP_TASK)
def catch_up_task() -> int:
    """Catch up the lagging team instances that answer again (beat)."""
    return len(catch_up(current_app.config["CLOUDSIM"]))


@shared_task(name="cloudsim.team_instances.poll")
def poll() -> int:
    """Check every live team instance (beat)."""
    return len(check_instances(current_app.config["CLOUDSIM"]))
