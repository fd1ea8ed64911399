"""Terminate on the servers provider: every machine cleaned through the route a launch uses
(sim and the field computers through the router, whose firewall closes their own addresses),
or the constellation left `terminate_incomplete` with which machine and why, and a retry."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pytest
from celery.contrib.testing.worker import start_worker
from click.testing import CliRunner
from flask import Flask
from libcloud.compute.base import Node, NodeAuthSSHKey

from cloudsim.auth.policy import SYSTEM
from cloudsim.cli import main
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations import service
from cloudsim.launched_constellations.keys import constellation_keypair
from cloudsim.models import Constellation, ConstellationState, JobState
from cloudsim.providers.service import configure_provider
from provisioners.providers.local.driver import LocalNodeDriver
from provisioners.providers.local.netns import connect_command, list_namespaces
from tests.conftest import running_app
from tests.launched_constellations.conftest import finished, hosts_config

from .keys import KeyPair, make_key_pair
from .shell import Shell

pytestmark = [pytest.mark.hosts, pytest.mark.timeout(3000)]  # two vrc launches, three terminates

PREFIX = f"cst{os.getpid() % 100000}"
# What a vrc launch leaves on a machine and its terminate must remove.
DIRT = (
    "for t in filter nat mangle raw; do iptables -t $t -S; done | grep -c CLOUDSIM- || true; "
    "test -e /opt/drcsim && echo drcsim || true; "
    "cat /root/.ssh/authorized_keys"
)
# Makes the cleanup's `rm -rf /etc/cloudsim` fail: an empty read-only mount inside it.
HOLD = "mkdir -p /etc/cloudsim/held && mount -t tmpfs -o ro tmpfs /etc/cloudsim/held"
RELEASE = "umount /etc/cloudsim/held"


@dataclass(frozen=True)
class Servers:
    """Four existing servers on one LAN (srv-r has a public address, the router's), and a
    fifth machine on that LAN, `outside`, standing for the controller's own place on it."""

    login: KeyPair
    nodes: dict[str, Node]
    outside: Node
    cidr: str

    def inventory(self, local: LocalNodeDriver) -> list[dict[str, object]]:
        """Return the inventory: the public server reached from the internet, the others at
        their LAN addresses from `outside`, which a vrc's firewall then closes."""
        entries: list[dict[str, object]] = []
        for name, node in self.nodes.items():
            address = node.private_ips[0]
            entry: dict[str, object] = {
                "name": name,
                "address": address,
                "private_ip": address,
                "network": "lab-lan",
                "cidr": self.cidr,
                "private_key": self.login.private,
                "proxy_command": connect_command(self.outside.extra["netns"], address, 22),
            }
            if node.public_ips:
                entry["public_ip"] = entry["address"] = node.public_ips[0]
                entry["proxy_command"] = local.ex_public_proxy_command(node.public_ips[0], 22)
            entries.append(entry)
        return entries

    def run(self, ssh: Shell, name: str, command: str) -> str:
        """Run a command as root on a server the test's own way (loopback, the lab key)."""
        node = self.nodes[name]
        return ssh.check(node.private_ips[0], node.extra["ssh_proxy_command"], self.login, command)


@pytest.fixture
def config(make_config: Callable[..., Config]) -> Config:
    return hosts_config(make_config, PREFIX, 224)


@pytest.fixture
def servers() -> Iterator[tuple[Servers, LocalNodeDriver]]:
    """Make four local hosts (one public) as the existing servers; destroy them after."""
    directory = Path(tempfile.mkdtemp(prefix=f"{PREFIX}-lab-"))
    local = LocalNodeDriver(
        state_dir=str(directory),
        prefix=f"{PREFIX}l",
        subnet_pool="10.225.0.0/16",
        public_cidr="198.18.25.0/24",
    )
    login = make_key_pair("inventory")
    try:
        network = local.ex_create_network("lab")
        names = {"srv-r": True, "srv-s": False, "srv-f1": False, "srv-f2": False, "out": False}
        with ThreadPoolExecutor(max_workers=len(names)) as pool:
            futures = {
                name: pool.submit(
                    local.create_node,
                    name=name,
                    auth=NodeAuthSSHKey(login.public_line),
                    ex_network=network,
                    ex_public=public,
                )
                for name, public in names.items()
            }
        nodes = {name: future.result() for name, future in futures.items()}
        outside = nodes.pop("out")
        yield Servers(login=login, nodes=nodes, outside=outside, cidr=network.cidr), local
    finally:
        for node in local.list_nodes():
            local.destroy_node(node)
        for network in local.ex_list_networks():
            local.ex_destroy_network(network)
        leftovers = list_namespaces(f"{PREFIX}l-")
        shutil.rmtree(directory)
    assert leftovers == []


@pytest.fixture
def app(config: Config) -> Iterator[Flask]:
    with running_app(config) as app:
        yield app


def test_a_vrc_terminated_on_servers_leaves_them_clean_or_says_which_is_not(
    app: Flask, config: Config, servers: tuple[Servers, LocalNodeDriver], encryption_key: str
) -> None:
    lab, local = servers
    configure_provider("servers", {"inventory": lab.inventory(local)})
    db.session.commit()
    ssh = Shell()
    try:
        with start_worker(
            app.extensions["celery"],
            pool="threads",
            concurrency=2,
            perform_ping_check=False,
            loglevel="WARNING",
            shutdown_timeout=30,
        ):
            constellation = _launch(app, "srv-vrc")
            blob = constellation_keypair(constellation).public.split()[1]
            placed = {m.name: str(m.provider_node_id) for m in constellation.machines}
            assert sorted(placed.values()) == ["srv-f1", "srv-f2", "srv-r", "srv-s"]
            assert "drcsim" in lab.run(ssh, placed["sim"], DIRT)
            lab.run(ssh, placed["fc2"], HOLD)

            job = service.terminate(SYSTEM, constellation.id)
            done = finished(job.id)
            assert done.state == JobState.FAILED
            db.session.refresh(constellation)
            assert constellation.state == ConstellationState.TERMINATE_INCOMPLETE
            assert constellation.error is not None
            assert constellation.error.startswith("terminate incomplete: fc2: ")
            assert "/etc/cloudsim" in constellation.error
            assert "router: kept" in constellation.error
            for machine in ("sim", "fc1"):  # cleaned, through the router
                _assert_clean(lab.run(ssh, placed[machine], DIRT), blob)
            listed = _orphans_listed(config, encryption_key)
            assert [o["name"] for o in listed if o.get("terminate_incomplete")] == ["srv-vrc"]

            lab.run(ssh, placed["fc2"], RELEASE)
            retried = finished(service.retry(SYSTEM, constellation.id).id)
            assert retried.state == JobState.SUCCEEDED, retried.error
            db.session.refresh(constellation)
            assert (constellation.state, constellation.error) == (
                ConstellationState.TERMINATED,
                None,
            )
            for name in placed.values():
                _assert_clean(lab.run(ssh, name, DIRT), blob)
            assert not [
                o for o in _orphans_listed(config, encryption_key) if o.get("terminate_incomplete")
            ]

            again = _launch(app, "srv-vrc2")  # the same servers take a new launch
            final = finished(service.terminate(SYSTEM, again.id).id)
            assert final.state == JobState.SUCCEEDED, final.error
    finally:
        ssh.close()


def _launch(app: Flask, name: str) -> Constellation:
    constellation, job = service.launch(SYSTEM, name=name, kind="vrc", provider="servers")
    done = finished(job.id, timeout=900)
    assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log[-3000:]}"
    db.session.refresh(constellation)
    assert constellation.state == ConstellationState.READY
    return constellation


def _assert_clean(dirt: str, blob: str) -> None:
    chains, *rest = dirt.splitlines()
    assert chains == "0", dirt
    assert "drcsim" not in rest, dirt
    assert blob not in dirt


def _orphans_listed(config: Config, encryption_key: str) -> list[dict[str, object]]:
    db.session.commit()
    env = {  # the command's own app, on the test's database and settings
        "CLOUDSIM_INSTANCE_DIR": str(config.instance_dir),
        "CLOUDSIM_DATABASE_URL": config.database_url,
        "CLOUDSIM_REDIS_URL": config.effective_redis_url,
        "CLOUDSIM_ENCRYPTION_KEYS": encryption_key,
        "CLOUDSIM_LOCAL_PREFIX": config.local_prefix,
        "CLOUDSIM_LOCAL_SUBNET_POOL": config.local_subnet_pool,
        "CLOUDSIM_LOCAL_PUBLIC_CIDR": config.local_public_cidr,
        # the test's own, not production's: the command's app also serves the test's worker
        "CLOUDSIM_SIM_MIN_RTF": str(config.sim_min_rtf),
        "CLOUDSIM_JOB_LEASE_SECONDS": str(config.job_lease_seconds),
    }
    result = CliRunner().invoke(main, ["constellation", "orphans", "--json"], env=env)
    assert result.exit_code == 0, result.output
    return list(json.loads(result.output))
