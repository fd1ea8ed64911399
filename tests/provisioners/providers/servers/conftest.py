"""Fixtures for the servers provider: state dirs and real "existing servers" made as local hosts.

The temporary directories are made with tempfile, not pytest's tmp_path: the latter sweeps
older pytest directories, and other suites' leftovers there can make that sweep warn.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from libcloud.compute.base import Node, NodeAuthSSHKey

from provisioners.providers.local.driver import LocalNodeDriver
from provisioners.providers.local.netns import list_namespaces

from .keys import KeyPair, make_key_pair
from .shell import Shell


@pytest.fixture
def state_dir() -> Iterator[Path]:
    """Return an empty directory for one driver's state, removed afterwards."""
    directory = Path(tempfile.mkdtemp(prefix="cloudsim-servers-state-"))
    yield directory
    shutil.rmtree(directory)


@dataclass(frozen=True)
class Lab:
    """Existing servers for the tests: local hosts on one LAN, and an inventory of them."""

    login: KeyPair
    nodes: dict[str, Node]
    cidr: str

    def inventory(self, **overrides: dict[str, Any]) -> list[dict[str, Any]]:
        """Return the inventory entries, with per-server field overrides."""
        return [
            {
                "name": name,
                "address": node.private_ips[0],
                "private_ip": node.private_ips[0],
                **({"public_ip": node.public_ips[0]} if node.public_ips else {}),
                "network": "lab-lan",
                "cidr": self.cidr,
                "private_key": self.login.private,
                "proxy_command": node.extra["ssh_proxy_command"],
                **overrides.get(name, {}),
            }
            for name, node in self.nodes.items()
        ]


@pytest.fixture(scope="module")
def lab() -> Iterator[Lab]:
    """Make two hosts on one LAN (srv-a with a public address, srv-b without); destroy them."""
    if os.geteuid() != 0:
        pytest.skip("the existing servers are local hosts, which need root")
    prefix = f"csv{os.getpid()}"
    directory = Path(tempfile.mkdtemp(prefix=f"{prefix}-local-"))
    local = LocalNodeDriver(
        state_dir=str(directory),
        prefix=prefix,
        subnet_pool="10.216.0.0/16",
        public_cidr="198.18.16.0/24",
    )
    login = make_key_pair("inventory")
    try:
        network = local.ex_create_network("lab")
        with ThreadPoolExecutor(max_workers=2) as pool:
            futures = {
                name: pool.submit(
                    local.create_node,
                    name=name,
                    auth=NodeAuthSSHKey(login.public_line),
                    ex_network=network,
                    ex_public=public,
                    ex_init="minimal",
                )
                for name, public in (("srv-a", True), ("srv-b", False))
            }
        yield Lab(login=login, nodes={n: f.result() for n, f in futures.items()}, cidr=network.cidr)
    finally:
        for node in local.list_nodes():
            local.destroy_node(node)
        for network in local.ex_list_networks():
            local.ex_destroy_network(network)
        leftovers = list_namespaces(f"{prefix}-")
        shutil.rmtree(directory)
    assert leftovers == []


@pytest.fixture
def ssh() -> Iterator[Shell]:
    """Return a way to run commands on hosts with a given key; close every connection after."""
    shell = Shell()
    yield shell
    shell.close()
