"""Destroy leaves nothing behind, failures and crashes clean up, reboot keeps the host's state."""

import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
from libcloud.compute.base import Node
from libcloud.compute.types import NodeState

from provisioners.providers.local import processes
from provisioners.providers.local.cgroups import host_cgroup_dirs
from provisioners.providers.local.driver import LocalNodeDriver
from provisioners.providers.local.errors import (
    HostBootError,
    LocalProviderError,
    NameInUseError,
    NetworkInUseError,
    NetworkNotFoundError,
)
from provisioners.providers.local.netns import list_namespaces

from .local_support import HostShell, SshKey, create_host, mounts_under, needs_root

pytestmark = [pytest.mark.hosts, needs_root]

Shells = Callable[[Node, SshKey], HostShell]


def _recorded_processes(node: Node) -> list[processes.ProcessId]:
    """Return the node's init and launcher as recorded, identified by start time."""
    found = [processes.identify(node.extra["pid"]), processes.identify(node.extra["launcher_pid"])]
    assert all(process is not None for process in found)
    return [process for process in found if process is not None]


def _assert_nothing_left(
    node: Node, state_dir: Path, prefix: str, pids: list[processes.ProcessId]
) -> None:
    assert node.extra["netns"] not in list_namespaces(f"{prefix}-")
    assert not any(process.pid and processes.is_alive(process) for process in pids)
    mounts = Path("/proc/mounts").read_text()
    assert node.extra["machine"] not in mounts
    assert not Path(f"/run/systemd/nspawn/propagate/{node.extra['machine']}").exists()
    assert not (state_dir / prefix / "nodes" / node.name).exists()
    assert not (state_dir / prefix / "hosts" / node.name).exists()
    assert not any(path.exists() for path in host_cgroup_dirs(node.extra["machine"]))


def test_destroy_removes_every_namespace_mount_process_and_file(
    driver: LocalNodeDriver, ssh_key: SshKey, state_dir: Path, host_prefix: str
) -> None:
    network = driver.ex_create_network("gone")
    nodes = [
        create_host(driver, "gone-boot", network, ssh_key, ex_public=True, ex_init="systemd"),
        create_host(driver, "gone-tini", network, ssh_key, ex_init="minimal"),
    ]
    recorded = {node.name: _recorded_processes(node) for node in nodes}
    with pytest.raises(NetworkInUseError, match="gone-boot, gone-tini"):
        driver.ex_destroy_network(network)

    for node in nodes:
        # Two destroys of the same node at once (a retried job, a reconciler) both succeed.
        with ThreadPoolExecutor(max_workers=2) as pool:
            assert list(pool.map(driver.destroy_node, [node, node])) == [True, True]
        _assert_nothing_left(node, state_dir, host_prefix, recorded[node.name])
        assert driver.destroy_node(node) is True
    assert driver.list_nodes() == []
    assert f"{host_prefix}-s-public" not in list_namespaces(f"{host_prefix}-")
    assert mounts_under(state_dir) == []

    assert driver.ex_destroy_network(network) is True
    assert driver.ex_destroy_network(network) is True
    assert list_namespaces(f"{host_prefix}-") == []
    with pytest.raises(NetworkNotFoundError, match="no public network"):
        driver.ex_public_proxy_command("198.18.0.2", 22)
    assert [path.name for path in state_dir.iterdir()] == [".lock"]


def test_systemd_hosts_do_not_manage_each_others_services(
    driver: LocalNodeDriver, ssh_key: SshKey, shells: Shells
) -> None:
    network = driver.ex_create_network("twins")
    nodes: list[Node] = []
    try:
        for name in ("twin-a", "twin-b"):
            nodes.append(create_host(driver, name, network, ssh_key, ex_init="systemd"))
        cgroups = [Path(f"/proc/{node.extra['pid']}/cgroup").read_text() for node in nodes]
        assert "/cst" in cgroups[0] and "-twin-a/" in cgroups[0]
        assert "/cst" in cgroups[1] and "-twin-b/" in cgroups[1]
        twin_a = shells(nodes[0], ssh_key)
        twin_a.check("systemctl stop ssh.service")
        assert twin_a.check("systemctl is-active ssh.service || true").strip() == "inactive"
        twin_b = shells(nodes[1], ssh_key)
        assert twin_b.check("systemctl is-active ssh.service").strip() == "active"
        # Destroying a must leave b's processes alone: b boots a service, a goes away.
        twin_b.check("systemd-run --unit=cloudsim-probe sleep 600")
        b_mountinfo = Path(f"/proc/{nodes[1].extra['launcher_pid']}/mountinfo")
        a_netns_mount = f"/run/netns/{nodes[0].extra['netns']} "
        assert a_netns_mount in b_mountinfo.read_text()
        twin_a.close()
        driver.destroy_node(nodes[0])
        assert twin_b.check("systemctl is-active cloudsim-probe.service").strip() == "active"
        # b's launcher began with a copy of the mount table naming a's namespace; deleting
        # that name must take the copy too, or it would keep a's namespace alive.
        assert a_netns_mount not in b_mountinfo.read_text()
        assert [n.state for n in driver.list_nodes()] == [NodeState.RUNNING]
        assert shells(nodes[1], ssh_key).check("hostname").strip() == "twin-b"
    finally:
        for node in nodes:
            driver.destroy_node(node)
        driver.ex_destroy_network(network)


@pytest.mark.parametrize(
    ("init", "reason", "evidence"),
    [
        ("minimal", "init exited before sshd listened", "/usr/sbin/sshd"),
        ("systemd", "ssh.service failed", "Failed to locate executable /usr/sbin/sshd"),
    ],
)
def test_failed_boot_raises_with_the_boot_log_and_cleans_up(
    make_driver: Callable[[], LocalNodeDriver],
    ssh_key: SshKey,
    state_dir: Path,
    host_prefix: str,
    init: str,
    reason: str,
    evidence: str,
) -> None:
    # A machine without sshd: it can never become ready.
    broken = LocalNodeDriver(
        state_dir=str(state_dir),
        prefix=host_prefix,
        hidden_paths=["/usr/sbin/sshd"],
        # systemd gives up on ssh.service well before this; create_node must not wait for it.
        boot_timeout=60,
    )
    network = broken.ex_create_network("doomed")
    try:
        with pytest.raises(HostBootError) as raised:
            create_host(broken, "doomed", network, ssh_key, ex_init=init)
        message = str(raised.value)
        assert message.startswith(f"creating node doomed failed: host doomed: {reason}\n")
        assert evidence in message.split("--- boot log of doomed")[1]
        assert make_driver().list_nodes() == []
        assert f"{host_prefix}-h-doomed" not in list_namespaces(f"{host_prefix}-")
        assert not (state_dir / host_prefix / "nodes" / "doomed").exists()
        assert not any(path.exists() for path in host_cgroup_dirs(f"{host_prefix}-doomed"))
        assert mounts_under(state_dir) == []
    finally:
        broken.ex_destroy_network(network)


def test_reboot_keeps_files_host_key_and_addresses(
    driver: LocalNodeDriver, ssh_key: SshKey, shells: Shells
) -> None:
    network = driver.ex_create_network("again", cidr="10.212.10.0/24", ex_gateway="10.212.10.1")
    assert network.gateway == "10.212.10.1"
    tenth = "10.212.10.9"
    node = create_host(driver, "again", network, ssh_key, ex_private_ip=tenth, ex_init="systemd")
    try:
        assert node.private_ips == [tenth]
        with pytest.raises(NameInUseError):
            create_host(driver, "again", network, ssh_key)
        first_init = processes.identify(node.extra["pid"])
        assert first_init is not None
        before = shells(node, ssh_key)
        before.check("echo kept > /root/kept.txt")
        assert before.check("ip route show default").split()[:3] == [
            "default",
            "via",
            "10.212.10.1",
        ]
        before.close()
        assert driver.reboot_node(node) is True
        rebooted = next(n for n in driver.list_nodes() if n.name == "again")
        assert rebooted.state == NodeState.RUNNING
        assert rebooted.extra["pid"] != node.extra["pid"]
        assert not processes.is_alive(first_init)
        after = shells(rebooted, ssh_key)
        assert after.check("cat /root/kept.txt").strip() == "kept"
        assert after.host_key.asbytes() == before.host_key.asbytes()
    finally:
        driver.destroy_node(node)
        driver.ex_destroy_network(network)


def test_a_host_whose_init_died_is_stopped_and_still_destroyed_cleanly(
    driver: LocalNodeDriver, ssh_key: SshKey, state_dir: Path, host_prefix: str
) -> None:
    network = driver.ex_create_network("crash")
    node = create_host(driver, "crash", network, ssh_key, ex_init="systemd")
    try:
        recorded = _recorded_processes(node)
        processes.kill(recorded[0], timeout=10)
        assert processes.wait_until_gone(recorded[1], timeout=10)
        assert [n.state for n in driver.list_nodes()] == [NodeState.STOPPED]
        with pytest.raises(
            LocalProviderError, match=r"will not run with private_ips: crash \(stopped\)"
        ):
            driver.wait_until_running([node], timeout=30)
    finally:
        driver.destroy_node(node)
        driver.ex_destroy_network(network)
    _assert_nothing_left(node, state_dir, host_prefix, recorded)


_CREATE_IN_CHILD = """
import sys
from libcloud.compute.base import NodeAuthSSHKey
from provisioners.providers.local.driver import LocalNodeDriver
state_dir, prefix, public_key = sys.argv[1:4]
# Without sshd the host never gets ready: create_node is still waiting when it is killed.
driver = LocalNodeDriver(state_dir=state_dir, prefix=prefix, hidden_paths=["/usr/sbin/sshd"])
network = driver.ex_get_network("orphan")
auth = NodeAuthSSHKey(public_key)
driver.create_node("orphan", None, None, auth=auth, ex_network=network, ex_init="systemd")
"""


def test_a_node_whose_creator_was_killed_is_error_and_destroyed_cleanly(
    driver: LocalNodeDriver, ssh_key: SshKey, state_dir: Path, host_prefix: str
) -> None:
    network = driver.ex_create_network("orphan")
    pidfile = state_dir / host_prefix / "nodes" / "orphan" / "launcher.pid"
    creator = subprocess.Popen(
        [sys.executable, "-c", _CREATE_IN_CHILD, str(state_dir), host_prefix, ssh_key.public_line]
    )
    try:
        deadline = time.monotonic() + 30
        while not (pidfile.exists() and pidfile.read_text().endswith("\n")):
            assert creator.poll() is None, "create_node ended before it launched the host"
            assert time.monotonic() < deadline, "the host was never launched"
            time.sleep(0.01)
        launcher = processes.identify(int(pidfile.read_text()))
        # The orchestrator dies in the middle of create_node.
        creator.kill()
        creator.wait()
        [orphan] = driver.list_nodes()
        assert orphan.state == NodeState.ERROR
        driver.destroy_node(orphan)
        assert launcher is None or not processes.is_alive(launcher)
        assert driver.list_nodes() == []
        assert f"{host_prefix}-h-orphan" not in list_namespaces(f"{host_prefix}-")
        assert mounts_under(state_dir) == []
    finally:
        if creator.poll() is None:
            creator.kill()
            creator.wait()
        driver.ex_destroy_network(network)


def test_sweep_removes_hosts_whose_records_were_lost(
    driver: LocalNodeDriver, ssh_key: SshKey, state_dir: Path, host_prefix: str
) -> None:
    network = driver.ex_create_network("lost")
    nodes = [
        create_host(driver, "lost-boot", network, ssh_key, ex_public=True, ex_init="systemd"),
        create_host(driver, "lost-tini", network, ssh_key, ex_init="minimal"),
    ]
    recorded = [process for node in nodes for process in _recorded_processes(node)]
    # What a wiped state_dir looks like: hosts still running, nothing on record.
    shutil.rmtree(state_dir / host_prefix / "nodes")
    shutil.rmtree(state_dir / host_prefix / "networks")
    assert driver.list_nodes() == []

    leaked = driver.ex_sweep()

    assert f"netns {host_prefix}-h-lost-boot" in leaked
    assert f"netns {host_prefix}-s-lost" in leaked
    assert any(item.startswith("cgroup ") and "lost-boot" in item for item in leaked)
    assert any(item.startswith("mount ") for item in leaked)
    assert not any(processes.is_alive(process) for process in recorded)
    assert list_namespaces(f"{host_prefix}-") == []
    assert not any(path.exists() for path in host_cgroup_dirs(f"{host_prefix}-lost-boot"))
    assert mounts_under(state_dir) == []
    assert [path.name for path in state_dir.iterdir()] == [".lock"]
    assert driver.ex_sweep() == []
