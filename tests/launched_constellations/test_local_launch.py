"""End to end on the local provider: launch, verify, two at once, sudo allowed during a launch,
terminate."""

from __future__ import annotations

import pytest
from flask import Flask

from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.errors import Conflict
from cloudsim.extensions import db
from cloudsim.launched_constellations import service
from cloudsim.launched_constellations.connect import machine_host_keys, targets
from cloudsim.launched_constellations.keys import constellation_keypair
from cloudsim.models import Constellation, ConstellationState, Job, JobState, MachineState
from cloudsim.people.service import create_team
from constellations.plans.members import MEMBERS_SUDOERS
from provisioners.remote.ssh import SSHExecutor
from tests.launched_constellations.conftest import access_refreshes, finished, leftovers
from tests.support.servers import wait_for

pytestmark = pytest.mark.hosts


def test_two_vrc_constellations_launch_verify_and_terminate_cleanly(
    constellations_app: Flask, constellations_worker: None, constellations_config: Config
) -> None:
    team = create_team(SYSTEM, "Late sudoers")
    launched = [
        service.launch(SYSTEM, name=name, kind="vrc", provider="local", team_id=team_id)
        for name, team_id in (("alpha", None), ("bravo", team.id))
    ]
    db.session.commit()  # the test is the boundary: its commit sends the launch jobs
    bravo, bravo_job = launched[1]
    _sudo_while_launching(bravo, bravo_job)
    for _, job in launched:
        done = finished(job.id)
        assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log[-3000:]}"
    _sudo_reaches_the_field_computers(bravo, finished(bravo_job.id), constellations_config)
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


def _sudo_while_launching(constellation: Constellation, job: Job) -> None:
    """An officer allows sudo while the launch is at `verify` (the field computers installed):
    nothing pushes it then."""

    def verifying() -> bool:
        db.session.expire_all()
        return db.session.get(Job, job.id).stage == "verify"  # type: ignore[union-attr]

    wait_for(verifying, 600, "the verify stage (the field computers are installed)")
    service.set_team_sudo(SYSTEM, constellation.id, True)
    db.session.commit()
    assert access_refreshes(constellation.id) == []  # still launching: nothing pushes it now


def _sudo_reaches_the_field_computers(
    constellation: Constellation, done: Job, config: Config
) -> None:
    """The launch, once ready, pushes the change it missed; the team's members have sudo on fc1."""
    assert "changed during the launch" in done.log
    (refresh,) = access_refreshes(constellation.id)
    assert finished(refresh.id).state == JobState.SUCCEEDED
    db.session.refresh(constellation)
    keys = constellation_keypair(constellation)
    reach = targets(constellation, keys, config)
    with SSHExecutor(machine_host_keys(constellation), secrets=[keys.private]) as executor:
        sudoers = executor.run(reach["fc1"], f"cat {MEMBERS_SUDOERS}", check=False)
    assert sudoers.ok and "NOPASSWD" in sudoers.stdout, sudoers.stderr
