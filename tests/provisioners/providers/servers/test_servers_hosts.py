"""The servers provider on real machines: local hosts stand in for the existing servers."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
from libcloud.compute.base import Node, NodeAuthSSHKey
from libcloud.compute.types import NodeState

from provisioners.providers.servers.driver import ServersNodeDriver
from provisioners.providers.servers.errors import (
    NetworkInUseError,
    NoFreeServerError,
    ServerSetupError,
)

from .conftest import Lab
from .keys import KeyPair, make_key_pair
from .shell import Shell

pytestmark = pytest.mark.hosts

TAGS = {"cloudsim:constellation": "c1", "cloudsim:role": "router"}
# Leftovers of a deploy, as CloudSim's plans make them (firewall, software, services, VPN).
DEPLOYED = """set -e
iptables -N CLOUDSIM-IN
iptables -A CLOUDSIM-IN -j ACCEPT
iptables -I INPUT -j CLOUDSIM-IN
iptables -I INPUT -i tun+ -j DROP
iptables -N CLOUDSIM-FWD
iptables -I FORWARD -j CLOUDSIM-FWD
iptables -t raw -N CLOUDSIM-OCU
iptables -t raw -I PREROUTING -j CLOUDSIM-OCU
iptables -t nat -A POSTROUTING -s 10.8.0.0/24 -d 10.216.9.0/24 -j MASQUERADE
sysctl -q -w net.ipv4.ip_forward=1
mkdir -p /opt/drcsim/bin /opt/cloudsim/wheelhouse /etc/cloudsim /etc/openvpn/server/cloudsim
touch /opt/drcsim/bin/drcsim /etc/sysctl.d/60-cloudsim.conf /etc/cloudsim/cloudsim.env
touch /etc/openvpn/server/cloudsim/server.key /etc/systemd/system/csrouter.service
printf '10.216.9.1 c1-router\\n' > /etc/hosts
printf 'CloudSim constellation c1\\n' > /etc/motd
"""
# What CloudSim changes, so that a release must restore it.
ORIGINALS = (
    "cat /etc/hosts /etc/motd; ip -4 route show default; hostname; "
    "sysctl -n net.ipv4.ip_forward; "
    "for table in filter nat mangle raw; do iptables -t $table -S; done"
)
LEFTOVERS = (
    "ls -d /opt/drcsim /opt/cloudsim /etc/cloudsim /etc/openvpn/server/cloudsim "
    "/etc/sysctl.d/60-cloudsim.conf /etc/systemd/system/csrouter.service "
    "/var/lib/cloudsim-servers 2>/dev/null; true"
)


def claim(
    driver: ServersNodeDriver, network_name: str, key: KeyPair, machines: dict[str, bool]
) -> dict[str, Node]:
    """Claim one server per machine (name -> public?) at once, as the engine does."""
    network = driver.ex_get_network(network_name)

    def create(machine: str) -> Node:
        return driver.create_node(
            name=f"{network_name}-{machine}",
            size=driver.list_sizes()[0],
            image=driver.list_images()[0],
            auth=NodeAuthSSHKey(key.public_line),
            ex_network=network,
            ex_public=machines[machine],
            ex_tags={
                "cloudsim:constellation": network_name,
                "cloudsim:machine": machine,
                "cloudsim:role": machine,
            },
        )

    with ThreadPoolExecutor(max_workers=len(machines)) as pool:
        futures = {machine: pool.submit(create, machine) for machine in machines}
    return {machine: future.result() for machine, future in futures.items()}


def on(node: Node) -> tuple[str, list[str]]:
    """Return how the engine reaches a node: its private address through its proxy command."""
    return node.private_ips[0], node.extra["ssh_proxy_command"]


def test_claim_use_rediscover_destroy_and_claim_again(
    lab: Lab, state_dir: Path, ssh: Shell
) -> None:
    driver = ServersNodeDriver(inventory=lab.inventory(), state_dir=str(state_dir))
    constellation = make_key_pair("constellation c1")
    originals = {
        name: ssh.check(*on(server), lab.login, ORIGINALS) for name, server in lab.nodes.items()
    }
    assert driver.ex_create_network("c1").cidr == lab.cidr
    nodes = claim(driver, "c1", constellation, {"router": True, "sim": False})

    router, sim = nodes["router"], nodes["sim"]
    assert (router.id, sim.id) == ("srv-a", "srv-b")
    assert router.public_ips == lab.nodes["srv-a"].public_ips and sim.public_ips == []
    assert sim.private_ips == lab.nodes["srv-b"].private_ips
    assert router.state == NodeState.RUNNING
    for node in nodes.values():
        assert ssh.check(*on(node), constellation, "hostname").strip() == node.name
        ssh.check(*on(node), constellation, DEPLOYED)
    ssh.check(*on(sim), constellation, f"ip -4 route replace default via {router.private_ips[0]}")
    again = driver.create_node(
        name="c1-sim", auth=NodeAuthSSHKey(constellation.public_line), ex_network="c1"
    )
    assert (again.id, again.name) == (sim.id, sim.name)

    fresh = ServersNodeDriver(inventory=lab.inventory(), state_dir=str(state_dir))
    found = {node.name: node for node in fresh.list_nodes()}
    assert sorted(found) == ["c1-router", "c1-sim"]
    assert found["c1-sim"].private_ips == sim.private_ips
    assert found["c1-sim"].extra["ssh_proxy_command"] == sim.extra["ssh_proxy_command"]
    assert all(node.state == NodeState.RUNNING for node in found.values())
    assert [n.name for n in fresh.ex_list_nodes_by_tags({"cloudsim:role": "sim"})] == ["c1-sim"]
    assert len(fresh.ex_list_nodes_by_tags({"cloudsim:constellation": "c1"})) == 2
    assert {s["name"]: s["node"] for s in fresh.ex_list_servers()} == {
        "srv-a": "c1-router",
        "srv-b": "c1-sim",
    }
    with pytest.raises(NoFreeServerError, match=r"no free server in network 'c1'.*2 server"):
        claim(fresh, "c1", constellation, {"fc1": False})
    with pytest.raises(NetworkInUseError, match="c1-router"):
        fresh.ex_destroy_network(fresh.ex_get_network("c1"))

    for node in found.values():
        assert fresh.destroy_node(node)
    for name, server in lab.nodes.items():
        assert ssh.check(*on(server), lab.login, "hostname").strip() == name
        assert ssh.check(*on(server), lab.login, ORIGINALS) == originals[name]
        assert ssh.check(*on(server), lab.login, LEFTOVERS) == ""
        keys = ssh.check(*on(server), lab.login, "cat /root/.ssh/authorized_keys")
        assert constellation.blob not in keys and lab.login.blob in keys
        assert not ssh.can_log_in(*on(server), constellation)
    assert all(fresh.destroy_node(node) for node in found.values())
    assert fresh.list_nodes() == []
    assert fresh.ex_destroy_network(fresh.ex_get_network("c1"))

    second = make_key_pair("constellation c2")
    driver.ex_create_network("c2")
    (node,) = claim(driver, "c2", second, {"sim": False}).values()
    assert node.id == "srv-b"
    assert ssh.check(*on(node), second, "hostname").strip() == "c2-sim"
    assert driver.destroy_node(node) and driver.ex_destroy_network("c2")


def test_an_unreachable_server_is_released_and_cleaned_before_its_next_claim(
    lab: Lab, state_dir: Path, ssh: Shell
) -> None:
    driver = ServersNodeDriver(inventory=lab.inventory(), state_dir=str(state_dir))
    first = make_key_pair("constellation c3")
    driver.ex_create_network("c3")
    (node,) = claim(driver, "c3", first, {"sim": False}).values()
    ssh.check(*on(node), first, DEPLOYED)

    unreachable = ServersNodeDriver(
        inventory=lab.inventory(**{"srv-b": {"proxy_command": ["false"]}}),
        state_dir=str(state_dir),
        connect_timeout=1,
    )
    assert unreachable.destroy_node(node)
    assert unreachable.list_nodes() == []
    (status,) = [s for s in unreachable.ex_list_servers() if s["name"] == "srv-b"]
    assert status["status"] == "free"
    assert "released without cleanup" in status["warning"]
    assert ssh.can_log_in(*on(node), first), "nothing could have been cleaned"
    assert list(unreachable.ex_clean_up_released()) == ["srv-b"]

    second = make_key_pair("constellation c4")
    (node,) = claim(driver, "c3", second, {"sim": False}).values()
    keys = ssh.check(*on(node), lab.login, "cat /root/.ssh/authorized_keys")
    assert first.blob not in keys and second.blob in keys
    # the earlier node's leftovers are gone; the server's originals are kept while claimed
    assert ssh.check(*on(node), lab.login, LEFTOVERS) == "/var/lib/cloudsim-servers\n"
    assert [s["warning"] for s in driver.ex_list_servers()] == [None, None]

    ssh.check(*on(node), second, DEPLOYED)
    assert unreachable.destroy_node(node) and unreachable.ex_destroy_network("c3")
    assert driver.ex_clean_up_released() == {}
    assert [s["warning"] for s in driver.ex_list_servers()] == [None, None]
    assert not ssh.can_log_in(*on(node), second)
    assert ssh.check(*on(node), lab.login, LEFTOVERS) == ""


def test_a_server_that_refuses_the_login_key_fails_its_claim(lab: Lab, state_dir: Path) -> None:
    stranger = make_key_pair("not installed anywhere")
    driver = ServersNodeDriver(
        inventory=lab.inventory(**{"srv-b": {"private_key": stranger.private}}),
        state_dir=str(state_dir),
        connect_timeout=1,
    )
    driver.ex_create_network("c5")
    with pytest.raises(ServerSetupError, match=r"srv-b.*could not be prepared"):
        claim(driver, "c5", make_key_pair("c5"), {"sim": False})
    (node,) = driver.list_nodes()
    assert (node.name, node.state, node.extra["status"]) == ("c5-sim", NodeState.ERROR, "failed")
    assert driver.destroy_node(node)
    assert driver.list_nodes() == []
    assert driver.ex_destroy_network("c5")


OPERATOR = "csoperator"
ADD_OPERATOR = f"""set -e
useradd --create-home --shell /bin/sh {OPERATOR}
install -d -m 700 -o {OPERATOR} -g {OPERATOR} /home/{OPERATOR}/.ssh
install -m 600 -o {OPERATOR} -g {OPERATOR} /root/.ssh/authorized_keys /home/{OPERATOR}/.ssh/
printf '%s ALL=(ALL) NOPASSWD: ALL\\n' {OPERATOR} > /etc/sudoers.d/{OPERATOR}
"""
REMOVE_OPERATOR = f"rm -f /etc/sudoers.d/{OPERATOR}; userdel --remove {OPERATOR}"


def test_a_login_user_other_than_root_works_through_sudo(
    lab: Lab, state_dir: Path, ssh: Shell
) -> None:
    server = lab.nodes["srv-b"]
    ssh.check(*on(server), lab.login, ADD_OPERATOR)
    try:
        driver = ServersNodeDriver(
            inventory=lab.inventory(**{"srv-b": {"user": OPERATOR}}), state_dir=str(state_dir)
        )
        key = make_key_pair("constellation c6")
        driver.ex_create_network("c6")
        (node,) = claim(driver, "c6", key, {"sim": False}).values()
        assert (node.id, node.extra["ssh_user"]) == ("srv-b", OPERATOR)
        installed = f"stat -c %U /home/{OPERATOR}/.ssh/authorized_keys; hostname"
        assert ssh.check(*on(server), lab.login, installed) == f"{OPERATOR}\nc6-sim\n"
        operator_keys = f"cat /home/{OPERATOR}/.ssh/authorized_keys"
        assert key.blob in ssh.check(*on(server), lab.login, operator_keys)
        assert driver.destroy_node(node) and driver.ex_destroy_network("c6")
        assert key.blob not in ssh.check(*on(server), lab.login, operator_keys)
        assert ssh.check(*on(server), lab.login, "hostname") == "srv-b\n"
    finally:
        ssh.check(*on(server), lab.login, REMOVE_OPERATOR)
