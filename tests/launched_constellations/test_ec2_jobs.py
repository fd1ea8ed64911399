"""The launch and terminate jobs' cloud stages on EC2 (moto's server through libcloud).

SSH stages cannot run here (moto's instances are not machines); the local-provider tests
cover them.
"""

from __future__ import annotations

import json

import pytest
from flask import Flask
from sqlalchemy import text

from cloudsim.auth.policy import SYSTEM
from cloudsim.errors import InvalidInput
from cloudsim.extensions import db
from cloudsim.jobs.runner import JobContext
from cloudsim.launched_constellations import service
from cloudsim.launched_constellations.jobs import (
    ensure_machines,
    ensure_network,
    terminate_constellation,
)
from cloudsim.launched_constellations.keys import constellation_keypair
from cloudsim.launched_constellations.lifecycle import ConstellationJob
from cloudsim.models import ConstellationState, Job
from cloudsim.providers.service import configure_provider, open_provider
from constellations.definition import load_kind
from tests.support.servers import MotoEndpoint

SECRET_KEY = "moto-secret-access-key-for-tests"


@pytest.fixture
def ec2(app: Flask, moto_endpoint: MotoEndpoint) -> None:
    settings = {
        "access_key": "AKIDTESTENGINE",
        "secret_key": SECRET_KEY,
        "region": "us-east-1",
        "image": "ami-placeholder",
        "sizes": {"default": "t3.micro"},
        "endpoint": moto_endpoint.url,
    }
    configure_provider("ec2", settings)
    images = open_provider("ec2", app.config["CLOUDSIM"]).driver.list_images(ex_owner="amazon")
    configure_provider("ec2", {**settings, "image": images[0].id})


def test_provider_settings_are_checked_and_stored_encrypted(app: Flask) -> None:
    with pytest.raises(InvalidInput, match="provider ec2 is not configured"):
        open_provider("ec2", app.config["CLOUDSIM"])
    with pytest.raises(InvalidInput, match="ec2 needs secret_key, image"):
        configure_provider("ec2", {"access_key": "AKID", "region": "us-east-1"})
    with pytest.raises(InvalidInput, match="endpoint must be an http"):
        configure_provider(
            "ec2",
            {
                "access_key": "A",
                "secret_key": "S",
                "region": "r",
                "image": "ami-1",
                "endpoint": "ftp://x",
            },
        )
    configure_provider(
        "ec2", {"access_key": "A", "secret_key": SECRET_KEY, "region": "r", "image": "ami-1"}
    )
    raw = db.session.execute(text("SELECT value FROM secrets")).scalar_one()
    assert SECRET_KEY not in raw and "ami-1" not in raw


def test_ec2_network_machines_and_terminate(app: Flask, ec2: None) -> None:
    constellation, launch_job = service.launch(SYSTEM, name="cloud7", kind="vrc", provider="ec2")
    kind = load_kind("vrc")
    provider = open_provider("ec2", app.config["CLOUDSIM"])
    ctx = JobContext(launch_job)
    keys = constellation_keypair(constellation)
    subnet = ensure_network(ctx, provider.driver, constellation, kind)
    nodes = ensure_machines(ctx, provider, constellation, kind, keys, subnet)
    by_machine = {n.extra["tags"]["cloudsim:machine"]: n for n in nodes}
    assert sorted(by_machine) == ["fc1", "fc2", "router", "sim"]
    assert by_machine["sim"].private_ips == [subnet.rsplit(".", 1)[0] + ".51"]
    assert by_machine["router"].public_ips and not by_machine["fc1"].public_ips
    groups = provider.driver.ex_apply_firewall(  # type: ignore[attr-defined]
        provider.driver.ex_get_network("cloud7"), list(kind.firewall), kind.roles
    )
    assert sorted(groups) == ["fc", "router", "sim"]
    again = ensure_machines(ctx, provider, constellation, kind, keys, subnet)  # a resumed job
    assert sorted(n.id for n in again) == sorted(n.id for n in nodes)
    assert len(provider.nodes("cloud7")) == 4

    terminate = service.terminate(SYSTEM, constellation.id)
    terminate_row = db.session.get(Job, terminate.id)
    assert terminate_row is not None
    terminate_constellation(JobContext(terminate_row), ConstellationJob.from_job(terminate_row))
    db.session.commit()  # as the runner does when the body returns
    db.session.refresh(constellation)
    assert constellation.state == ConstellationState.TERMINATED
    assert provider.nodes("cloud7") == []
    assert "cloud7" not in [n.name for n in provider.driver.ex_list_networks()]
    audit = json.dumps([m.verification for m in constellation.machines])
    assert SECRET_KEY not in audit
