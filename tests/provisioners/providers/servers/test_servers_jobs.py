"""The launch jobs' stages on the servers provider: network, machines, the real plans, release."""

from __future__ import annotations

from pathlib import Path

import pytest
from flask import Flask
from libcloud.compute.base import Node, NodeAuthSSHKey

from cloudsim.auth.policy import SYSTEM
from cloudsim.extensions import db
from cloudsim.jobs.runner import JobContext
from cloudsim.launched_constellations import lifecycle, service
from cloudsim.launched_constellations.connect import (
    machine_host_keys,
    record_routes,
    targets,
)
from cloudsim.launched_constellations.jobs import (
    ensure_machines,
    ensure_network,
    release_made_since,
)
from cloudsim.launched_constellations.keys import constellation_keypair
from cloudsim.models import ConstellationState, Secret
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
# What a launch leaves on a machine and its release must remove.
DIRT = (
    "iptables -S | grep -c CLOUDSIM- || true; "
    "test -e /opt/drcsim && echo drcsim || true; "
    "cat /root/.ssh/authorized_keys"
)
# Makes the cleanup's `rm -rf /etc/cloudsim` fail: an empty read-only mount inside it.
HOLD = "mkdir -p /etc/cloudsim/held && mount -t tmpfs -o ro tmpfs /etc/cloudsim/held"
RELEASE = "umount /etc/cloudsim/held"


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


@pytest.mark.hosts
def test_a_launch_stopped_after_its_terminate_cleans_its_machines_through_the_router(
    app: Flask, lab: Lab, state_dir: Path, ssh: Shell
) -> None:
    """The launch's machines are cleaned through the route a launch uses (sim through the
    router, its own address closed by a vrc-like firewall), with the launch's key, which the
    finished terminate has deleted; one not cleaned turns the constellation incomplete."""
    private = lab.nodes["srv-b"]
    login = (private.private_ips[0], private.extra["ssh_proxy_command"], lab.login)
    before = ssh.check(*login, ORIGINALS)
    config = app.config["CLOUDSIM"]
    constellation, job = service.launch(SYSTEM, name="srv-late", kind="vrc", provider="local")
    kind = load_kind("vrc")
    driver = ServersNodeDriver(inventory=lab.inventory(), state_dir=str(state_dir))
    provider = Provider("servers", driver)
    ctx = JobContext(job)
    keys = constellation_keypair(constellation)
    ensure_network(ctx, driver, constellation, kind)
    rows = {m.name: m for m in constellation.machines}
    made: dict[str, Node] = {}
    for name, public in (("router", True), ("sim", False)):  # made before the launch stopped
        made[name] = driver.create_node(
            name=f"srv-late-{name}",
            auth=NodeAuthSSHKey(keys.public),
            ex_network=driver.ex_get_network(constellation.name),
            ex_public=public,
            ex_tags={"cloudsim:constellation": constellation.name, "cloudsim:machine": name},
        )
        rows[name].provider_node_id = str(made[name].id)
        rows[name].public_ip = made[name].public_ips[0] if made[name].public_ips else None
        rows[name].private_ip = made[name].private_ips[0]
    record_routes(constellation, provider, made.values())
    db.session.commit()  # as the launch does: its threads record host keys on the rows
    router_ip = made["router"].private_ips[0]
    with SSHExecutor(machine_host_keys(constellation), secrets=[keys.private]) as executor:
        sim = targets(constellation, keys, config)["sim"]
        assert sim.jump is not None and sim.jump.name == "srv-late/router"
        executor.run(  # the vrc firewall: sim's SSH from the router only
            sim,
            "mkdir -p /opt/drcsim && iptables -N CLOUDSIM-IN && "
            f"iptables -A CLOUDSIM-IN -p tcp --dport 22 ! -s {router_ip} -j DROP && "
            f"iptables -I INPUT -j CLOUDSIM-IN && {HOLD}",
        )
    # the terminate ended meanwhile: the machines' rows terminated, the key deleted
    db.session.query(Secret).filter_by(
        owner_type="constellation", owner_id=constellation.id
    ).delete()
    lifecycle.terminated(constellation)
    db.session.commit()

    release_made_since(ctx, constellation, provider, keys, config)
    db.session.commit()
    db.session.refresh(constellation)
    assert constellation.state == ConstellationState.TERMINATE_INCOMPLETE
    assert (constellation.error or "").startswith("terminate incomplete: router: kept, ")
    assert "sim: server srv-b is not cleaned up: " in (constellation.error or "")
    assert keys.private not in (constellation.error or "")
    assert constellation_keypair(constellation) == keys  # stored again, for the retry
    assert sorted(n.name for n in provider.nodes(constellation.name)) == [
        "srv-late-router",
        "srv-late-sim",
    ]

    with SSHExecutor(machine_host_keys(constellation), secrets=[keys.private]) as executor:
        executor.run(targets(constellation, keys, config)["sim"], RELEASE)
    release_made_since(ctx, constellation, provider, constellation_keypair(constellation), config)
    db.session.commit()
    assert provider.nodes(constellation.name) == [] and driver.ex_list_networks() == []
    assert [s["warning"] for s in driver.ex_list_servers() if s.get("warning")] == []
    assert ssh.check(*login, ORIGINALS) == before  # reached at its own address again
    dirt = ssh.check(*login, DIRT)
    assert dirt.splitlines()[0] == "0" and "drcsim" not in dirt, dirt
    assert keys.public.split()[1] not in dirt
