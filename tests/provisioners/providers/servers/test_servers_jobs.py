"""The launch jobs' stages on the servers provider: network, machines, the real plans, release."""

from __future__ import annotations

from pathlib import Path

import pytest
from flask import Flask

from cloudsim.auth.policy import SYSTEM
from cloudsim.jobs.runner import JobContext
from cloudsim.launched_constellations import service
from cloudsim.launched_constellations.connect import (
    machine_host_keys,
    record_routes,
    targets,
)
from cloudsim.launched_constellations.jobs import ensure_machines, ensure_network
from cloudsim.launched_constellations.keys import constellation_keypair
from cloudsim.providers.service import Provider
from constellations.definition import load_kind
from constellations.plans import PLANS, PlanContext, firewall
from provisioners.providers.base import CloudSimNodeDriver
from provisioners.providers.servers.driver import ServersNodeDriver
from provisioners.remote.operations import Operation, apply
from provisioners.remote.ssh import SSHExecutor

from .conftest import Lab
from .shell import Shell

# What a release must give back untouched.
ORIGINALS = "cat /etc/hosts /etc/motd; iptables -S; hostname"


@pytest.mark.hosts
def test_a_simple_constellation_runs_on_a_server_and_leaves_nothing_behind(
    app: Flask, lab: Lab, state_dir: Path, ssh: Shell
) -> None:
    server = lab.nodes["srv-a"]
    login = (server.private_ips[0], server.extra["ssh_proxy_command"], lab.login)
    before = ssh.check(*login, ORIGINALS)
    # The row names a provider the app knows; the stages get the servers provider itself.
    constellation, job = service.launch(SYSTEM, name="srv-simple", kind="simple", provider="local")
    kind = load_kind("simple")
    driver = ServersNodeDriver(inventory=lab.inventory(), state_dir=str(state_dir))
    provider = Provider("servers", driver)
    ctx = JobContext(job)
    keys = constellation_keypair(constellation)

    subnet = ensure_network(ctx, driver, constellation, kind)
    nodes = ensure_machines(ctx, provider, constellation, kind, keys, subnet)
    again = ensure_machines(ctx, provider, constellation, kind, keys, subnet)  # a resumed job
    (sim,) = constellation.machines
    assert subnet == lab.cidr
    assert [node.id for node in nodes] == [node.id for node in again] == ["srv-a"]
    # the server's own addresses, not the kind's host number 51
    assert (sim.private_ip, sim.public_ip) == (server.private_ips[0], server.public_ips[0])

    plan_context = PlanContext(
        constellation=constellation.name,
        team="",
        kind=kind,
        machine=kind.machine("sim"),
        subnet=subnet,
        addresses={"sim": sim.private_ip or ""},
    )
    plan = [*firewall(plan_context), *PLANS["common"](plan_context)]
    record_routes(constellation, provider, nodes)
    assert sim.ssh_route == {
        "host": server.private_ips[0],
        "user": "root",
        "port": 22,
        "proxy_command": server.extra["ssh_proxy_command"],
        "jump": None,
    }
    with SSHExecutor(machine_host_keys(constellation), secrets=[keys.private]) as executor:
        target = targets(constellation, keys, app.config["CLOUDSIM"])["sim"]
        assert executor.run(target, "hostname").stdout == "srv-simple-sim\n"
        for operation in plan:
            assert isinstance(operation, Operation)
            apply(executor, target, operation)
        deployed = executor.run(target, ORIGINALS).stdout
    assert "-A INPUT -j CLOUDSIM-IN" in deployed and "srv-simple" in deployed

    for node in provider.nodes(constellation.name):
        assert driver.destroy_node(node)
    assert driver.ex_destroy_network(driver.ex_get_network(constellation.name))
    assert provider.nodes() == [] and driver.ex_list_networks() == []
    assert ssh.check(*login, ORIGINALS) == before


def test_the_servers_driver_is_a_cloudsim_driver() -> None:
    assert issubclass(ServersNodeDriver, CloudSimNodeDriver)
