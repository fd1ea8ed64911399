"""End to end on the local provider: launch, verify, two at once, terminate, kill the worker."""

from __future__ import annotations

import pytest
from flask import Flask

from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.errors import Conflict
from cloudsim.extensions import db
from cloudsim.launched_constellations import service
from cloudsim.models import ConstellationState, JobState, MachineState
from tests.launched_constellations.conftest import finished, leftovers

pytestmark = pytest.mark.hosts


def test_two_vrc_constellations_launch_verify_and_terminate_cleanly(
    constellations_app: Flask, constellations_worker: None, constellations_config: Config
) -> None:
    launched = [
        service.launch(SYSTEM, name=name, kind="vrc", provider="local")
        for name in ("alpha", "bravo")
    ]
    for _, job in launched:
        done = finished(job.id)
        assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log[-3000:]}"
    subnets = set()
    for constellation, _ in launched:
        db.session.refresh(constellation)
        assert constellation.state == ConstellationState.READY
        machines = {m.name: m for m in constellation.machines}
        assert sorted(machines) == ["fc1", "fc2", "router", "sim"]
        assert all(m.state == MachineState.READY and m.host_key for m in machines.values())
        assert machines["router"].public_ip and not machines["sim"].public_ip
        subnet = constellation.resources["subnet"]
        subnets.add(subnet)
        assert machines["sim"].private_ip.endswith(".51")
        checks = [c for m in machines.values() for c in m.verification["checks"]]
        assert len(checks) == 18 and all(c["ok"] for c in checks), checks
        denied = {(c["from"], c["to"], c["port"]) for c in checks if c["expected"] == "closed"}
        assert {("fc1", "sim", 22), ("fc2", "sim", 22), ("fc1", "router", 22)} <= denied
        assert {("vpn", "sim", 22), ("vpn", "router", 22)} <= denied  # a VPN client of its own
        assert any(c.get("after") == "revocation" for c in checks)  # then cut off
        assert machines["sim"].verification["simulator"]["ok"]
    assert len(subnets) == 2

    jobs = [service.terminate(SYSTEM, constellation.id) for constellation, _ in launched]
    for job in jobs:
        assert finished(job.id).state == JobState.SUCCEEDED
    assert leftovers(constellations_config) == {"netns": [], "mounts": [], "files": []}
    for constellation, _ in launched:
        db.session.refresh(constellation)
        assert constellation.state == ConstellationState.TERMINATED
        with pytest.raises(Conflict, match="already terminated"):
            service.terminate(SYSTEM, constellation.id)
