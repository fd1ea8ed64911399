"""Orphan nodes: a node whose constellation is not live is reported by the periodic check and
destroyed on request; a live constellation's node is left alone."""

from __future__ import annotations

import pytest
from flask import Flask
from libcloud.compute.base import NodeAuthSSHKey
from sqlalchemy import select

from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations.keys import generate_keypair
from cloudsim.launched_constellations.reconcile import destroy_orphans, find_orphans, reconcile
from cloudsim.models import AuditEvent, Constellation, ConstellationState
from cloudsim.providers.service import open_provider

pytestmark = pytest.mark.hosts


def test_a_node_of_a_terminated_constellation_is_reported_then_destroyed(
    constellations_app: Flask, constellations_config: Config
) -> None:
    owner = Constellation(
        name="ghost", kind="simple", provider="local", state=ConstellationState.READY
    )
    db.session.add(owner)
    db.session.commit()
    driver = open_provider("local", constellations_config).driver
    node = driver.create_node(
        name="ghost-sim",
        size=driver.list_sizes()[0],
        image=driver.list_images()[0],
        auth=NodeAuthSSHKey(generate_keypair("ghost").public),
        ex_network=driver.ex_create_network("ghost"),
        ex_tags={"cloudsim:constellation": "ghost", "cloudsim:machine": "sim"},
    )
    assert find_orphans(constellations_config) == []  # its constellation is live

    owner.state = ConstellationState.TERMINATED
    db.session.commit()
    assert reconcile() == 1  # the periodic check reports, never destroys
    found = db.session.scalar(
        select(AuditEvent).where(AuditEvent.action == "provider.orphans_found")
    )
    assert found is not None and found.details["nodes"] == ["ghost-sim"]
    assert [n.id for n in driver.list_nodes()] == [node.id]

    [orphan] = destroy_orphans(SYSTEM, constellations_config)
    assert (orphan.provider, orphan.name, orphan.constellation) == ("local", "ghost-sim", "ghost")
    assert driver.list_nodes() == []
    assert find_orphans(constellations_config) == []
