"""State records, the state lock, process identity and unit masking: no root needed."""

import fcntl
import os
import subprocess
import sys
import threading
from dataclasses import replace
from pathlib import Path

import pytest

from provisioners.providers.local import processes
from provisioners.providers.local.cgroups import host_cgroup_dirs
from provisioners.providers.local.host import units_to_mask
from provisioners.providers.local.processes import ProcessId
from provisioners.providers.local.state import NetworkRecord, NodeRecord, StateStore


def _node(name: str) -> NodeRecord:
    return NodeRecord(
        id=f"id-{name}",
        name=name,
        network="lan",
        netns=f"cs-h-{name}",
        machine=f"cs-{name}",
        init="minimal",
        private_ip="10.211.0.2",
        tags={"role": "sim"},
        launcher=ProcessId(10, 20),
        init_process=ProcessId(11, 21),
    )


def test_node_records_round_trip_through_json(scratch: Path) -> None:
    store = StateStore(scratch, "cs")
    store.write_node(_node("sim"))
    again = StateStore(scratch, "cs").find_node("sim")
    assert again == _node("sim")
    assert again is not None and again.init_process == ProcessId(11, 21)
    assert [record.name for record in store.read_nodes()] == ["sim"]


def test_deleting_a_node_removes_its_directory(scratch: Path) -> None:
    store = StateStore(scratch, "cs")
    store.write_node(_node("sim"))
    (store.node_dir("sim") / "boot.log").write_text("booted\n")
    store.delete_node("sim")
    store.delete_node("sim")
    assert store.find_node("sim") is None
    store.remove_empty_dirs()
    assert list(scratch.iterdir()) == []


def test_prefixes_see_their_own_records_but_share_subnet_knowledge(scratch: Path) -> None:
    first, second = StateStore(scratch, "csa"), StateStore(scratch, "csb")
    first.write_network(NetworkRecord("lan", "10.211.0.0/24", "csa-s-lan"))
    second.write_network(NetworkRecord("lan", "10.211.1.0/24", "csb-s-lan"))
    assert [record.cidr for record in first.read_networks()] == ["10.211.0.0/24"]
    assert sorted(record.cidr for record in first.read_all_prefixes_networks()) == [
        "10.211.0.0/24",
        "10.211.1.0/24",
    ]


def test_the_lock_excludes_other_holders_until_released(scratch: Path) -> None:
    store = StateStore(scratch, "cs")
    with store.lock(), open(scratch / ".lock") as other:
        with pytest.raises(BlockingIOError):
            fcntl.flock(other, fcntl.LOCK_EX | fcntl.LOCK_NB)
    with open(scratch / ".lock") as other:
        fcntl.flock(other, fcntl.LOCK_EX | fcntl.LOCK_NB)
        fcntl.flock(other, fcntl.LOCK_UN)


def test_the_lock_serialises_threads(scratch: Path) -> None:
    store = StateStore(scratch, "cs")
    counter_file = scratch / "counter"
    counter_file.write_text("0")

    def increment() -> None:
        for _ in range(50):
            with store.lock():
                counter_file.write_text(str(int(counter_file.read_text()) + 1))

    workers = [threading.Thread(target=increment) for _ in range(4)]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join()
    assert counter_file.read_text() == "200"


def test_a_process_is_identified_by_pid_and_start_time() -> None:
    me = processes.identify(os.getpid())
    assert me is not None and processes.is_alive(me)
    assert not processes.is_alive(replace(me, start_time=me.start_time + 1))
    # After a reboot the same PID may well start at the same tick again.
    assert not processes.is_alive(replace(me, boot_id="an-earlier-boot"))


def test_an_exited_process_is_not_alive() -> None:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    recorded = processes.identify(child.pid)
    child.wait()
    assert recorded is None or not processes.is_alive(recorded)
    assert processes.identify(child.pid) is None


def test_units_enabled_on_the_base_image_are_masked_except_ssh(scratch: Path) -> None:
    wants = scratch / "multi-user.target.wants"
    wants.mkdir()
    for unit in ("postgresql.service", "redis-server.service", "ssh.service", "remote-fs.target"):
        (wants / unit).symlink_to(f"/lib/systemd/system/{unit}")
    timers = scratch / "timers.target.wants"
    timers.mkdir()
    (timers / "apt-daily.timer").symlink_to("/lib/systemd/system/apt-daily.timer")
    assert units_to_mask(scratch) == [
        "apt-daily.timer",
        "console-getty.service",
        "postgresql.service",
        "redis-server.service",
    ]


def test_this_machines_enabled_services_would_be_masked_but_not_sshd() -> None:
    masked = units_to_mask()
    assert "ssh.service" not in masked
    if Path("/etc/systemd/system/multi-user.target.wants/postgresql.service").exists():
        assert "postgresql.service" in masked


def test_host_cgroups_sit_at_the_top_of_the_systemd_hierarchies(scratch: Path) -> None:
    (scratch / "mountinfo").write_text(
        "31 23 0:28 / /sys/fs/cgroup rw,relatime - tmpfs tmpfs rw,mode=755\n"
        "35 31 0:32 / /sys/fs/cgroup/memory rw,relatime - cgroup cgroup rw,memory\n"
        "40 31 0:37 / /sys/fs/cgroup/systemd rw,relatime - cgroup cgroup rw,name=systemd\n"
        "41 31 0:38 / /sys/fs/cgroup/unified rw,relatime - cgroup2 cgroup2 rw\n"
    )
    assert host_cgroup_dirs("cs-router", proc=scratch) == (
        Path("/sys/fs/cgroup/systemd/cs-router"),
        Path("/sys/fs/cgroup/unified/cs-router"),
    )


def test_host_cgroups_on_a_pure_cgroup2_machine(scratch: Path) -> None:
    (scratch / "mountinfo").write_text(
        "30 23 0:26 / /sys/fs/cgroup rw,nosuid - cgroup2 cgroup2 rw,nsdelegate\n"
    )
    assert host_cgroup_dirs("cs-sim", proc=scratch) == (Path("/sys/fs/cgroup/cs-sim"),)
