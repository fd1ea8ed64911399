"""Networks: refused requests, parallel subnet allocation, isolation between networks."""

import threading
from collections.abc import Callable
from ipaddress import ip_network

import pytest
from libcloud.compute.base import Node

from provisioners.providers.local.driver import LocalNodeDriver
from provisioners.providers.local.errors import (
    AddressError,
    InvalidRequestError,
    NameInUseError,
    NetworkNotFoundError,
)
from provisioners.providers.local.netns import list_namespaces

from .local_support import HostShell, SshKey, create_host, needs_root

pytestmark = [pytest.mark.hosts, needs_root]

Shells = Callable[[Node, SshKey], HostShell]


def test_bad_requests_are_refused_before_anything_is_made(
    driver: LocalNodeDriver, ssh_key: SshKey, host_prefix: str
) -> None:
    network = driver.ex_create_network("strict", cidr="10.212.9.0/24")
    try:
        with pytest.raises(AddressError, match="not a host address"):
            create_host(driver, "stray", network, ssh_key, ex_private_ip="10.9.9.9")
        with pytest.raises(InvalidRequestError, match="NodeAuthSSHKey"):
            driver.create_node("nokey", None, None, ex_network=network)
        with pytest.raises(InvalidRequestError, match="ex_init"):
            create_host(driver, "badinit", network, ssh_key, ex_init="upstart")
        with pytest.raises(AddressError, match="overlaps"):
            driver.ex_create_network("clash", cidr="10.212.9.128/25")
        with pytest.raises(NameInUseError):
            driver.ex_create_network("strict")
        with pytest.raises(InvalidRequestError, match="reserved"):
            driver.ex_create_network("public")
        assert driver.list_nodes() == []
        assert [n.name for n in driver.ex_list_networks()] == ["strict"]
    finally:
        driver.ex_destroy_network(network)
    with pytest.raises(NetworkNotFoundError):
        driver.ex_get_network("strict")
    assert list_namespaces(f"{host_prefix}-") == []


def test_networks_created_at_once_by_two_drivers_get_distinct_subnets(
    make_driver: Callable[[], LocalNodeDriver],
) -> None:
    drivers = [make_driver(), make_driver()]
    created: dict[str, str] = {}

    def create(index: int) -> None:
        network = drivers[index % 2].ex_create_network(f"par{index}")
        created[network.name] = network.cidr

    threads = [threading.Thread(target=create, args=(index,)) for index in range(6)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    try:
        subnets = [ip_network(cidr) for cidr in created.values()]
        assert len(subnets) == 6
        assert not any(a.overlaps(b) for i, a in enumerate(subnets) for b in subnets[i + 1 :])
        assert {n.name: n.cidr for n in make_driver().ex_list_networks()} == created
    finally:
        for network in make_driver().ex_list_networks():
            drivers[0].ex_destroy_network(network)


def test_two_networks_cannot_reach_each_other(
    driver: LocalNodeDriver, ssh_key: SshKey, shells: Shells
) -> None:
    blue, red = driver.ex_create_network("blue"), driver.ex_create_network("red")
    nodes: list[Node] = []
    try:
        for network in (blue, red):
            nodes.append(
                create_host(driver, f"{network.name}-sim", network, ssh_key, ex_init="minimal")
            )
        assert not ip_network(blue.cidr).overlaps(ip_network(red.cidr))
        blue_sim, red_sim = (shells(node, ssh_key) for node in nodes)
        # Even when told that red's subnet is on its own wire, blue finds nobody there.
        blue_sim.check(f"ip route add {red.cidr} dev eth0")
        assert blue_sim.run(f"ping -c 1 -W 1 {nodes[1].private_ips[0]}")[0] != 0
        red_sim.check(f"ip route add {blue.cidr} dev eth0")
        assert red_sim.run(f"ping -c 1 -W 1 {nodes[0].private_ips[0]}")[0] != 0
        # Each one does reach its own switch's broadcast domain: itself.
        blue_sim.check(f"ping -c 1 -W 1 {nodes[0].private_ips[0]}")
    finally:
        for node in nodes:
            driver.destroy_node(node)
        for network in (blue, red):
            driver.ex_destroy_network(network)
