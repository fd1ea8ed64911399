"""A network with a public systemd host and a LAN-only minimal host, checked over real SSH."""

import os
import select
import subprocess
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from ipaddress import ip_address, ip_network
from pathlib import Path

import pytest
from libcloud.compute.base import Node
from libcloud.compute.types import NodeState

from provisioners.providers.local import processes
from provisioners.providers.local.driver import LocalNodeDriver
from provisioners.providers.local.network import LocalNetwork

from .local_support import HostShell, SshKey, needs_root

pytestmark = [pytest.mark.hosts, needs_root]

Shells = Callable[[Node, SshKey], HostShell]


@dataclass(frozen=True)
class Lan:
    """The module's network and its two hosts."""

    network: LocalNetwork
    router: Node
    sim: Node


@pytest.fixture(scope="module")
def lan(driver: LocalNodeDriver, ssh_key: SshKey) -> Iterator[Lan]:
    """Create network "lan" with router (public, systemd) and sim (LAN only, minimal)."""
    network = driver.ex_create_network("lan")
    created: list[Node] = []
    try:
        created.append(
            driver.create_node(
                "router", driver.list_sizes()[0], driver.list_images()[0],
                auth=ssh_key.auth, ex_network=network, ex_public=True,
                ex_tags={"role": "router"}, ex_init="systemd",
            )
        )  # fmt: skip
        created.append(
            driver.create_node(
                "sim", driver.list_sizes()[0], driver.list_images()[0],
                auth=ssh_key.auth, ex_network=network, ex_tags={"role": "sim"}, ex_init="minimal",
            )
        )  # fmt: skip
        yield Lan(network=network, router=created[0], sim=created[1])
    finally:
        for node in created:
            driver.destroy_node(node)
        driver.ex_destroy_network(network)


def test_nodes_carry_addresses_tags_and_how_to_reach_them(lan: Lan) -> None:
    subnet = ip_network(lan.network.cidr)
    assert ip_address(lan.router.private_ips[0]) in subnet
    assert ip_address(lan.sim.private_ips[0]) in subnet
    assert ip_address(lan.router.public_ips[0]) in ip_network("198.18.0.0/24")
    assert lan.sim.public_ips == []
    assert lan.router.extra["tags"] == {"role": "router"}
    assert (lan.router.extra["init"], lan.sim.extra["init"]) == ("systemd", "minimal")
    assert lan.router.extra["network"] == lan.sim.extra["network"] == "lan"
    for node in (lan.router, lan.sim):
        assert node.state == NodeState.RUNNING
        assert Path("/run/netns", node.extra["netns"]).exists()
        assert f"--net=/run/netns/{node.extra['netns']}" in node.extra["ssh_proxy_command"]


def test_each_host_has_its_own_hostname_and_host_key(
    lan: Lan, ssh_key: SshKey, shells: Shells
) -> None:
    router, sim = shells(lan.router, ssh_key), shells(lan.sim, ssh_key)
    assert router.check("hostname").strip() == "router"
    assert sim.check("hostname").strip() == "sim"
    assert router.host_key.asbytes() != sim.host_key.asbytes()
    controller_keys = {
        path.read_text().split()[1] for path in Path("/etc/ssh").glob("ssh_host_*_key.pub")
    }
    assert router.host_key.get_base64() not in controller_keys
    assert sim.host_key.get_base64() not in controller_keys


def test_each_host_has_its_own_etc(lan: Lan, ssh_key: SshKey, shells: Shells) -> None:
    marker = "/etc/cloudsim-local-test-marker"
    router, sim = shells(lan.router, ssh_key), shells(lan.sim, ssh_key)
    router.check(f"echo written-on-router > {marker}")
    assert router.check(f"cat {marker}").strip() == "written-on-router"
    assert sim.run(f"test -e {marker}")[0] == 1
    assert not Path(marker).exists()


def test_controller_secrets_are_hidden_from_hosts(
    lan: Lan, ssh_key: SshKey, shells: Shells, controller_secret: Path, state_dir: Path
) -> None:
    assert controller_secret.exists()
    for node in (lan.router, lan.sim):
        shell = shells(node, ssh_key)
        for path in (controller_secret, state_dir / ".lock"):
            assert shell.run(f"test -e {path}")[0] == 1, f"{path} is visible on {node.name}"
        assert shell.run(f"ls -A {controller_secret.parent}")[1].strip() == ""
        assert sorted(shell.check("ls -A /root").split()) == [".bashrc", ".profile", ".ssh"]
        assert shell.check("ls -A /root/.ssh").split() == ["authorized_keys"]
        assert shell.check("ls -A /home").strip() == ""
        for server_data in ("/var/lib/postgresql", "/etc/postgresql"):
            if Path(server_data).is_dir():
                assert shell.check(f"ls -A {server_data}").strip() == ""
        # The rest of the machine's root is there: hosts run its programs.
        shell.check("test -x /usr/sbin/sshd && test -s /etc/os-release")


def test_pid_1_is_the_hosts_own_init(lan: Lan, ssh_key: SshKey, shells: Shells) -> None:
    router, sim = shells(lan.router, ssh_key), shells(lan.sim, ssh_key)
    assert router.check("cat /proc/1/comm").strip() == "systemd"
    assert sim.check("cat /proc/1/comm").strip() == "tini"
    # The controller's processes are invisible inside a host.
    assert int(sim.check("ls /proc | grep -c '^[0-9]'")) < 10
    for node, command in ((lan.router, "systemd"), (lan.sim, "tini")):
        assert Path(f"/proc/{node.extra['pid']}/comm").read_text().strip() == command
        # Each host sits in cgroups of its own, apart from its creator's and other hosts'.
        cgroups = Path(f"/proc/{node.extra['pid']}/cgroup").read_text()
        assert f":/{node.extra['machine']}" in cgroups


def test_systemd_host_boots_with_ssh_and_base_image_services_masked(
    lan: Lan, ssh_key: SshKey, shells: Shells
) -> None:
    router = shells(lan.router, ssh_key)
    assert router.check("systemctl is-active ssh").strip() == "active"
    for unit in ("postgresql.service", "redis-server.service"):
        status, out, _ = router.run(f"systemctl is-enabled {unit}")
        assert out.strip() == "masked", f"{unit}: {out} (exit {status})"
    state = router.run("systemctl is-system-running --wait", timeout=60)[1].strip()
    assert state in ("running", "degraded")


def test_hosts_can_forward_and_open_tun(lan: Lan, ssh_key: SshKey, shells: Shells) -> None:
    for node in (lan.router, lan.sim):
        shell = shells(node, ssh_key)
        shell.check("sysctl -w net.ipv4.ip_forward=1")
        assert shell.check("cat /proc/sys/net/ipv4/ip_forward").strip() == "1"
        shell.check("ip tuntap add dev tun9 mode tun && ip link delete tun9")
    assert Path("/proc/sys/net/ipv4/ip_forward").read_text().strip() in ("0", "1")


def test_hosts_cannot_touch_the_machines_disks_or_kernel_tunables(
    lan: Lan, ssh_key: SshKey, shells: Shells
) -> None:
    swappiness = Path("/proc/sys/vm/swappiness").read_text()
    for node in (lan.router, lan.sim):
        shell = shells(node, ssh_key)
        assert shell.check("find /dev -type b | wc -l").strip() == "0"
        assert shell.run("mknod /tmp/disk b 254 0")[0] != 0
        assert shell.run("sysctl -w vm.swappiness=7")[0] != 0
        # Only this host's mounts: nothing of the machine's own mount table shows through.
        assert "/run/netns" not in shell.check("cat /proc/1/mountinfo")
    assert Path("/proc/sys/vm/swappiness").read_text() == swappiness


def test_lan_hosts_reach_each_other(lan: Lan, ssh_key: SshKey, shells: Shells) -> None:
    router, sim = shells(lan.router, ssh_key), shells(lan.sim, ssh_key)
    sim.check(f"ping -c 1 -W 2 {lan.router.private_ips[0]}")
    router.check(f"ping -c 1 -W 2 {lan.sim.private_ips[0]}")


def test_public_host_routes_to_the_internet_and_lan_host_has_no_default_route(
    lan: Lan, ssh_key: SshKey, shells: Shells
) -> None:
    router, sim = shells(lan.router, ssh_key), shells(lan.sim, ssh_key)
    assert router.check("ip route show default").split()[:5] == [
        "default", "via", "198.18.0.1", "dev", "eth1",
    ]  # fmt: skip
    router.check("ping -c 1 -W 2 198.18.0.1")
    assert sim.check("ip route show default").strip() == ""


def _banner_from_public_side(driver: LocalNodeDriver, ip: str) -> tuple[bytes, int]:
    """Connect from "the internet" to ip:22; return what came back first and the exit status."""
    # stdin stays open until the banner is in: at EOF socat would hang up after 0.5 s.
    proxy = subprocess.Popen(
        driver.ex_public_proxy_command(ip, 22),
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
    )
    assert proxy.stdin is not None and proxy.stdout is not None
    received = b""
    deadline = time.monotonic() + 20
    while b"\n" not in received and time.monotonic() < deadline:
        ready, _, _ = select.select([proxy.stdout], [], [], deadline - time.monotonic())
        chunk = os.read(proxy.stdout.fileno(), 256) if ready else b""
        if not chunk:
            break
        received += chunk
    proxy.stdin.close()
    status = proxy.wait(timeout=20)
    proxy.stdout.close()
    return received, status


def test_public_side_reaches_router_but_not_lan_only_host(
    driver: LocalNodeDriver, lan: Lan
) -> None:
    banner, _status = _banner_from_public_side(driver, lan.router.public_ips[0])
    assert banner.startswith(b"SSH-2.0-")
    nothing, status = _banner_from_public_side(driver, lan.sim.private_ips[0])
    assert status != 0
    assert nothing == b""


def test_fresh_driver_rediscovers_running_nodes(
    lan: Lan, make_driver: Callable[[], LocalNodeDriver]
) -> None:
    fresh = make_driver()
    found = {node.name: node for node in fresh.list_nodes()}
    assert set(found) == {"router", "sim"}
    for original in (lan.router, lan.sim):
        again = found[original.name]
        assert again.state == NodeState.RUNNING
        assert again.id == original.id
        assert again.extra["pid"] == original.extra["pid"]
        assert again.private_ips == original.private_ips
        assert again.public_ips == original.public_ips
    assert [network.cidr for network in fresh.ex_list_networks()] == [lan.network.cidr]
    running = fresh.wait_until_running([found["router"], found["sim"]], timeout=10)
    assert [(node.name, ips) for node, ips in running] == [
        ("router", lan.router.private_ips),
        ("sim", lan.sim.private_ips),
    ]


def test_recorded_pid_is_identified_by_start_time(lan: Lan) -> None:
    init = processes.identify(lan.sim.extra["pid"])
    assert init is not None and processes.is_alive(init)
    assert not processes.is_alive(replace(init, start_time=init.start_time + 1))
    assert not processes.is_alive(replace(init, boot_id="an-earlier-boot"))
