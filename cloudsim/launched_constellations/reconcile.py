"""Find (and on request destroy) provider nodes that no live constellation in the database owns."""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass

from celery import shared_task
from flask import current_app
from libcloud.compute.base import Node
from sqlalchemy import select

from cloudsim.audit.service import record
from cloudsim.auth.policy import SYSTEM, Actor
from cloudsim.config import Config
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.models import Constellation, ConstellationState
from cloudsim.providers.service import PROVIDERS, open_provider, provider_settings

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Orphan:
    """A node at a provider that the database does not account for."""

    provider: str
    node_id: str
    name: str
    constellation: str | None


def _providers_in_reach(config: Config) -> list[str]:
    """Return the providers to look at: local when root, clouds once configured."""
    reachable = []
    for name in PROVIDERS:
        if name == "local":
            if os.geteuid() == 0:  # without root there can be no local nodes of ours either
                reachable.append(name)
            continue
        try:
            provider_settings(name)
        except CloudSimError:
            continue
        reachable.append(name)
    return reachable


def _orphan_nodes(config: Config) -> list[tuple[Orphan, Node]]:
    """Return every node whose constellation is unknown or already terminated, with its node."""
    live = set(
        db.session.scalars(
            select(Constellation.name).where(Constellation.state != ConstellationState.TERMINATED)
        )
    )
    orphans = []
    for provider in _providers_in_reach(config):
        for node in open_provider(provider, config).nodes():
            owner = node.extra.get("tags", {}).get("cloudsim:constellation")
            if owner not in live:
                orphans.append((Orphan(provider, str(node.id), node.name, owner), node))
    return orphans


def find_orphans(config: Config) -> list[Orphan]:
    """Return every node whose constellation is unknown or already terminated."""
    return [orphan for orphan, _ in _orphan_nodes(config)]


def incomplete_terminations() -> list[Constellation]:
    """Return the constellations whose terminate left a machine not cleaned (to retry)."""
    return list(
        db.session.scalars(
            select(Constellation)
            .where(Constellation.state == ConstellationState.TERMINATE_INCOMPLETE)
            .order_by(Constellation.name)
        )
    )


def destroy_orphans(actor: Actor, config: Config) -> list[Orphan]:
    """Destroy every orphan node; return what was destroyed."""
    orphans = _orphan_nodes(config)
    for orphan, node in orphans:
        node.destroy()
        record(
            "provider.orphan_destroyed",
            actor,
            target_type="node",
            target_id=orphan.node_id,
            provider=orphan.provider,
            name=orphan.name,
        )
    return [orphan for orphan, _ in orphans]


@shared_task(name="cloudsim.launched_constellations.reconcile")
def reconcile() -> int:
    """Report orphan nodes in the worker log and the audit trail (never destroys by itself)."""
    orphans = find_orphans(current_app.config["CLOUDSIM"])
    for orphan in orphans:
        log.warning(
            "orphan node %s (%s) at %s: constellation %s is not live",
            orphan.name,
            orphan.node_id,
            orphan.provider,
            orphan.constellation,
        )
    if orphans:
        record(
            "provider.orphans_found", SYSTEM, count=len(orphans), nodes=[o.name for o in orphans]
        )
    return len(orphans)
